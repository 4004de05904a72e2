"""Numba kernels of one explicit MPM step (2D plane strain, uniform grid padded by PAD ghost layers).

Grid node (i, j) sits at origin + ((i - PAD) h, (j - PAD) h); the grid box (walls) spans nodes PAD .. PAD + nx.
Shape weights come from shapes.weights3 (bspline2 boundary-modified at the box) and are evaluated from the
positions at the start of the step (x^n) in every transfer of the step.
Grid arrays: G[i, j, :] = (m, p_x, p_y, f_x, f_y) and V[i, j, :] = (v0_x, v0_y, v1_x, v1_y) (velocity before /
after the force update; MUSL overwrites v0 with the remapped velocity once the FLIP increment is taken).
Transfers (Sulsky 1994 USL; MUSL after Sulsky, Zhou & Schreyer 1995 / Nairn 2003; Jiang et al. 2015 APIC):
  p2g        : mass, momentum (+ affine C (x_i - x_p) for APIC), internal -V sigma.grad N, body and point forces
  grid       : v1 = (p + f dt) / m, boundary conditions per side
  gather     : FLIP v += sum N (v1 - v0) (USL/MUSL) or APIC v = sum N v1, C = sum v1 (x) grad N;
               x += dt sum N v1; L = sum v (x) grad N, F <- (I + L dt) F, V = V0 det F, stress update + return
  musl_remap : MUSL only: m_p v_p^{n+1} mapped back with the same S(x^n), BCs, L from the remapped velocity

Determinism / threads: P2G scatters in parallel over x-strips of STRIP cells, even strips first, then odd ones;
two strips of one colour share no node (a point's support spans at most 3 nodes), and inside a strip points are
taken in index order (stable counting sort), so every node sum has one fixed order whatever the thread count.
The gathers are per point. Results are bitwise identical for any number of threads (tests/test_mpm_core.py).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from coupler.mpm.materials import stress_update
from coupler.mpm.shapes import first_node, weights3

PAD = 2
STRIP = 2      # cells per P2G strip; needs STRIP >= support - 1 = 2 so that strips s and s + 2 share no node
CHUNK = 512    # points per work item of the gathers


@njit(cache=True)
def check_inside(x, lo0, lo1, hi0, hi1):
    """Index of the first point outside [lo, hi] or a NaN position, -1 if none."""
    for p in range(x.shape[0]):
        a, b = x[p, 0], x[p, 1]
        if not (a >= lo0 and a <= hi0 and b >= lo1 and b <= hi1):
            return p
    return -1


def n_strips(NX: int) -> int:
    return (NX + STRIP - 1) // STRIP


@njit(cache=True)
def strip_sort(kind, x, org0, h, start, cursor, order):
    """Stable counting sort of the points by the x-strip of their first support node (positions already checked
    inside the grid). On return the points of strip s are order[start[s]:start[s + 1]], in index order."""
    ns = start.shape[0] - 1
    start[:] = 0
    ih = 1.0 / h
    n = x.shape[0]
    for p in range(n):
        s = first_node(kind, (x[p, 0] - org0) * ih + PAD) // STRIP
        cursor[p] = s           # cursor is (n,) scratch: the strip of point p
        start[s + 1] += 1
    for s in range(ns):
        start[s + 1] += start[s]
    fill = start[:ns].copy()
    for p in range(n):
        s = cursor[p]
        order[fill[s]] = p
        fill[s] += 1


@njit(cache=True, inline="always")
def _p2g_point(p, kind, x, v, C, m, vol, s, lp, fext, org0, org1, h, ih, hx, hy, g0, g1, apic, G):
    xp, yp = x[p, 0], x[p, 1]
    i0, wx, dwx = weights3(kind, (xp - org0) * ih + PAD, lp[p], PAD, hx)
    j0, wy, dwy = weights3(kind, (yp - org1) * ih + PAD, lp[p], PAD, hy)
    mp = m[p]
    Vh = vol[p] * ih
    sxx, syy, sxy = s[p, 0], s[p, 1], s[p, 2]
    vx, vy = v[p, 0], v[p, 1]
    bx = mp * g0 + fext[p, 0]
    by = mp * g1 + fext[p, 1]
    c00 = c01 = c10 = c11 = 0.0
    if apic:
        c00, c01, c10, c11 = C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1]
    rx0 = (i0 - PAD) * h + org0 - xp
    ry0 = (j0 - PAD) * h + org1 - yp
    for a in range(3):
        i = i0 + a
        rx = rx0 + a * h
        for b in range(3):
            j = j0 + b
            N = wx[a] * wy[b]
            dNx = dwx[a] * wy[b]          # x h (ih folded into Vh)
            dNy = wx[a] * dwy[b]
            ux, uy = vx, vy
            if apic:
                ry = ry0 + b * h
                ux += c00 * rx + c01 * ry
                uy += c10 * rx + c11 * ry
            Nm = N * mp
            G[i, j, 0] += Nm
            G[i, j, 1] += Nm * ux
            G[i, j, 2] += Nm * uy
            G[i, j, 3] += N * bx - Vh * (sxx * dNx + sxy * dNy)
            G[i, j, 4] += N * by - Vh * (sxy * dNx + syy * dNy)


@njit(cache=True, parallel=True)
def p2g(kind, x, v, C, m, vol, s, lp, fext, org0, org1, h, nx, ny, g0, g1, apic, start, order, G):
    """Scatter of all points (strip-coloured, see module docstring). G is zeroed first."""
    NX = G.shape[0]
    hx, hy = float(PAD + nx), float(PAD + ny)
    for i in prange(NX):
        G[i] = 0.0
    ih = 1.0 / h
    ns = start.shape[0] - 1
    for color in range(2):
        for k in prange((ns - color + 1) // 2):
            st = 2 * k + color
            for q in range(start[st], start[st + 1]):
                _p2g_point(order[q], kind, x, v, C, m, vol, s, lp, fext, org0, org1, h, ih, hx, hy, g0, g1, apic,
                           G)


@njit(cache=True)
def point_forces(kind, xb, fb, org0, org1, h, nx, ny, G):
    """Spread point loads of boundary particles onto the grid (boundary particles carry no mass). Only nodes
    holding mass receive force; the weights are renormalised over them so the total load is kept exactly."""
    hx, hy = float(PAD + nx), float(PAD + ny)
    for p in range(xb.shape[0]):
        i0, wx, _ = weights3(kind, (xb[p, 0] - org0) / h + PAD, 0.25, PAD, hx)
        j0, wy, _ = weights3(kind, (xb[p, 1] - org1) / h + PAD, 0.25, PAD, hy)
        tot = 0.0
        for a in range(3):
            for b in range(3):
                if G[i0 + a, j0 + b, 0] > 1e-300:
                    tot += wx[a] * wy[b]
        if tot <= 0.0:
            continue
        for a in range(3):
            for b in range(3):
                if G[i0 + a, j0 + b, 0] > 1e-300:
                    N = wx[a] * wy[b] / tot
                    G[i0 + a, j0 + b, 3] += N * fb[p, 0]
                    G[i0 + a, j0 + b, 4] += N * fb[p, 1]


@njit(cache=True)
def apply_bc(V, off, nx, ny, bc, mu):
    """BCs on the velocity pair V[:, :, off:off+2]. Sides: 0 left, 1 right, 2 bottom, 3 top; bc 0 fixed, 1 slip,
    2 friction, 3 open. Nodes on or beyond a side: the normal velocity into the wall is removed (separation
    allowed); friction reduces the tangential speed by mu |dv_n| (Coulomb, Bardenhagen et al. 2001); fixed sets
    both components to 0."""
    NX, NY = V.shape[0], V.shape[1]
    for side in range(4):
        k = bc[side]
        if k == 3:
            continue
        if side < 2:
            r0, r1 = (0, PAD + 1) if side == 0 else (PAD + nx, NX)
            for i in range(r0, r1):
                for j in range(NY):
                    V[i, j, off], V[i, j, off + 1] = wall_velocity(V[i, j, off], V[i, j, off + 1], 0,
                                                                   1.0 if side == 0 else -1.0, k, mu[side])
        else:
            r0, r1 = (0, PAD + 1) if side == 2 else (PAD + ny, NY)
            for i in range(NX):
                for j in range(r0, r1):
                    V[i, j, off], V[i, j, off + 1] = wall_velocity(V[i, j, off], V[i, j, off + 1], 1,
                                                                   1.0 if side == 2 else -1.0, k, mu[side])


@njit(cache=True, inline="always")
def wall_velocity(ux, uy, d, nrm, k, mu):
    """Velocity (ux, uy) at a wall with inward normal nrm e_d under BC kind k (see apply_bc)."""
    if k == 0:
        return 0.0, 0.0
    if k == 3:
        return ux, uy
    un = (ux if d == 0 else uy) * nrm
    if un >= 0.0:
        return ux, uy
    ut = uy if d == 0 else ux
    if k == 2:
        red = mu * (-un)
        if abs(ut) <= red:
            ut = 0.0
        else:
            ut = ut - red * (1.0 if ut > 0 else -1.0)
    return (0.0, ut) if d == 0 else (ut, 0.0)


@njit(cache=True, parallel=True)
def grid_update(G, dt, V, nx, ny, bc, mu, alpha):
    """v0 = p / m, v1 = (p + f dt) / m, then BCs on both. alpha: local non-viscous damping (Cundall 1987),
    f <- f - alpha |f| sign(p); 0 = none."""
    NX, NY = G.shape[0], G.shape[1]
    for i in prange(NX):
        for j in range(NY):
            mm = G[i, j, 0]
            if mm > 1e-300:
                for d in range(2):
                    pd = G[i, j, 1 + d]
                    f = G[i, j, 3 + d]
                    if alpha > 0.0 and pd != 0.0:
                        f -= alpha * abs(f) * (1.0 if pd > 0.0 else -1.0)
                    V[i, j, d] = pd / mm
                    V[i, j, 2 + d] = (pd + f * dt) / mm
            else:
                for d in range(4):
                    V[i, j, d] = 0.0
    apply_bc(V, 0, nx, ny, bc, mu)
    apply_bc(V, 2, nx, ny, bc, mu)


@njit(cache=True)
def _gather_range(lo, hi, stage, kind, x, v, C, F, vol, vol0, s, eps_p, prm, mid, lp, org0, org1, h, nx, ny, dt, V,
                  mode, box):
    """Points [lo, hi), weights at the current x (= x^n). stage 0: USL/APIC full update (velocity, position,
    deformation, stress); 1: MUSL velocity only; 2: MUSL position from v1 + L from the remapped velocity V[.., 0:2]
    + stress. Returns 2 p for the first point with a non-finite stress, 2 p + 1 for one whose new position is
    outside box = (lo0, lo1, hi0, hi1) or not finite, -1 if none."""
    ih = 1.0 / h
    hx, hy = float(PAD + nx), float(PAD + ny)
    lgo = 0 if stage == 2 else 2      # velocity pair used for L
    flip = stage == 1 or (stage == 0 and mode == 0)
    for p in range(lo, hi):
        xp, yp = x[p, 0], x[p, 1]
        i0, wx, dwx = weights3(kind, (xp - org0) * ih + PAD, lp[p], PAD, hx)
        j0, wy, dwy = weights3(kind, (yp - org1) * ih + PAD, lp[p], PAD, hy)
        px = py = dvx = dvy = 0.0
        l00 = l01 = l10 = l11 = 0.0
        for a in range(3):
            i = i0 + a
            for b in range(3):
                j = j0 + b
                N = wx[a] * wy[b]
                ux, uy = V[i, j, 2], V[i, j, 3]
                px += N * ux
                py += N * uy
                if flip:
                    dvx += N * (ux - V[i, j, 0])
                    dvy += N * (uy - V[i, j, 1])
                if stage != 1:
                    dNx = dwx[a] * wy[b]
                    dNy = wx[a] * dwy[b]
                    gx, gy = V[i, j, lgo], V[i, j, lgo + 1]
                    l00 += gx * dNx
                    l01 += gx * dNy
                    l10 += gy * dNx
                    l11 += gy * dNy
        if stage == 1:
            v[p, 0] += dvx
            v[p, 1] += dvy
            continue
        l00, l01, l10, l11 = l00 * ih, l01 * ih, l10 * ih, l11 * ih
        if stage == 0:
            if mode == 2:
                v[p, 0], v[p, 1] = px, py
            else:
                v[p, 0] += dvx
                v[p, 1] += dvy
        C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1] = l00, l01, l10, l11
        xn, yn = xp + dt * px, yp + dt * py
        x[p, 0], x[p, 1] = xn, yn
        # deformation gradient, volume, stress (strain increment d = sym(L) dt, spin W_xy dt)
        l00, l01, l10, l11 = l00 * dt, l01 * dt, l10 * dt, l11 * dt
        f00, f01, f10, f11 = F[p, 0], F[p, 1], F[p, 2], F[p, 3]
        F[p, 0] = f00 + l00 * f00 + l01 * f10
        F[p, 1] = f01 + l00 * f01 + l01 * f11
        F[p, 2] = f10 + l10 * f00 + l11 * f10
        F[p, 3] = f11 + l10 * f01 + l11 * f11
        vol[p] = vol0[p] * (F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2])
        r = stress_update(prm[mid[p]], s[p, 0], s[p, 1], s[p, 2], s[p, 3], l00, l11, l01 + l10, 0.5 * (l01 - l10),
                          dt)
        s[p, 0], s[p, 1], s[p, 2], s[p, 3] = r[0], r[1], r[2], r[3]
        eps_p[p] += r[4]
        if not (np.isfinite(r[0]) and np.isfinite(r[1]) and np.isfinite(r[2]) and np.isfinite(r[3])):
            return 2 * p
        if not (xn >= box[0] and xn <= box[2] and yn >= box[1] and yn <= box[3]):
            return 2 * p + 1
    return -1


@njit(cache=True, parallel=True)
def gather(stage, kind, x, v, C, F, vol, vol0, s, eps_p, prm, mid, lp, org0, org1, h, nx, ny, dt, V, mode, box):
    """Per-point gather over fixed chunks (see _gather_range); returns the code of the first bad point or -1."""
    n = x.shape[0]
    nc = (n + CHUNK - 1) // CHUNK
    bad = np.full(nc, -1, np.int64)
    for c in prange(nc):
        bad[c] = _gather_range(c * CHUNK, min(n, (c + 1) * CHUNK), stage, kind, x, v, C, F, vol, vol0, s, eps_p,
                               prm, mid, lp, org0, org1, h, nx, ny, dt, V, mode, box)
    for c in range(nc):
        if bad[c] >= 0:
            return bad[c]
    return -1


@njit(cache=True, parallel=True)
def musl_remap(kind, x, v, m, lp, org0, org1, h, start, order, G, V, nx, ny, bc, mu):
    """MUSL: p_i = sum S_ip(x^n) m_p v_p^{n+1} (same strips and order as p2g), V[.., 0:2] = p_i / m_i with the
    mass of this step's P2G, then the BCs."""
    ih = 1.0 / h
    hx, hy = float(PAD + nx), float(PAD + ny)
    NX, NY = G.shape[0], G.shape[1]
    for i in prange(NX):
        for j in range(NY):
            G[i, j, 1] = 0.0
            G[i, j, 2] = 0.0
    ns = start.shape[0] - 1
    for color in range(2):
        for k in prange((ns - color + 1) // 2):
            st = 2 * k + color
            for q in range(start[st], start[st + 1]):
                p = order[q]
                i0, wx, _ = weights3(kind, (x[p, 0] - org0) * ih + PAD, lp[p], PAD, hx)
                j0, wy, _ = weights3(kind, (x[p, 1] - org1) * ih + PAD, lp[p], PAD, hy)
                mvx, mvy = m[p] * v[p, 0], m[p] * v[p, 1]
                for a in range(3):
                    for b in range(3):
                        N = wx[a] * wy[b]
                        G[i0 + a, j0 + b, 1] += N * mvx
                        G[i0 + a, j0 + b, 2] += N * mvy
    for i in prange(NX):
        for j in range(NY):
            mm = G[i, j, 0]
            if mm > 1e-300:
                V[i, j, 0] = G[i, j, 1] / mm
                V[i, j, 1] = G[i, j, 2] / mm
            else:
                V[i, j, 0] = 0.0
                V[i, j, 1] = 0.0
    apply_bc(V, 0, nx, ny, bc, mu)


@njit(cache=True)
def advect_boundary(kind, xb, vb, wall, org0, org1, h, nx, ny, dt, G, V, bc, mu):
    """Boundary particles move like material points, x += dt v, with v the grid velocity v1 interpolated with
    weights renormalised over the nodes holding mass (empty nodes carry no velocity; a point on the outline has
    part of its support outside the body). A point created on a side that is not open (wall[p] = side, the
    outline of a body placed against that wall) stays attached to it: its velocity follows the side's BC
    (wall_velocity) with no normal component, so it slides along the wall and its normal coordinate stays exactly
    the wall's. (Linear and boundary-modified B-spline weights give the wall node's velocity on the wall, but GIMP
    mixes in the first interior node there, and the wall node may separate by round-off: either would let the
    point drift to the other side of the wall by round-off.) Positions are never clipped; the caller checks every
    point inside the grid before each transfer."""
    hx, hy = float(PAD + nx), float(PAD + ny)
    for p in range(xb.shape[0]):
        xp, yp = xb[p, 0], xb[p, 1]
        i0, wx, _ = weights3(kind, (xp - org0) / h + PAD, 0.25, PAD, hx)
        j0, wy, _ = weights3(kind, (yp - org1) / h + PAD, 0.25, PAD, hy)
        ux = uy = tot = 0.0
        for a in range(3):
            for b in range(3):
                if G[i0 + a, j0 + b, 0] > 1e-300:
                    N = wx[a] * wy[b]
                    tot += N
                    ux += N * V[i0 + a, j0 + b, 2]
                    uy += N * V[i0 + a, j0 + b, 3]
        if tot > 0.0:
            ux, uy = ux / tot, uy / tot
        side = wall[p]
        if side >= 0:
            d = 0 if side < 2 else 1
            ux, uy = wall_velocity(ux, uy, d, 1.0 if side % 2 == 0 else -1.0, bc[side], mu[side])
            if d == 0:
                ux = 0.0
            else:
                uy = 0.0
        vb[p, 0], vb[p, 1] = ux, uy
        xb[p, 0] = xp + dt * ux
        xb[p, 1] = yp + dt * uy
