"""Numba kernels of one explicit MPM step (2D plane strain, uniform grid padded by PAD ghost layers).

Grid node (i, j) sits at origin + ((i - PAD) h, (j - PAD) h). Shape weights come from shapes.weights_1d.
Transfers (Sulsky 1994 USL; Sulsky & Schreyer / Nairn MUSL; Jiang et al. 2015 APIC):
  p2g      : mass, momentum (+ affine C (x_i - x_p) for APIC), internal -V sigma.grad N, body and point forces
  grid     : v_new = (p + f dt) / m, boundary conditions per side
  g2p      : FLIP velocity update (USL/MUSL) or PIC + affine (APIC), position with grid velocity
  musl_remap: MUSL: particle momentum mapped back to the grid (BCs again) before the velocity gradient
  stress   : L = sum v_i (x) grad N_i, F <- (I + L dt) F, V = V0 det F, Jaumann stress update + return map
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from coupler.mpm.materials import update_stress
from coupler.mpm.shapes import weights_1d

PAD = 2


@njit(cache=True)
def check_inside(x, lo0, lo1, hi0, hi1):
    """Index of the first point outside [lo, hi] or a NaN position, -1 if none."""
    for p in range(x.shape[0]):
        a, b = x[p, 0], x[p, 1]
        if not (a >= lo0 and a <= hi0 and b >= lo1 and b <= hi1):
            return p
    return -1


@njit(cache=True)
def p2g(kind, x, v, C, m, vol, s, lp, fext, org0, org1, h, g0, g1, apic, gm, gp, gf):
    gm[:] = 0.0
    gp[:] = 0.0
    gf[:] = 0.0
    wx = np.empty(3)
    dwx = np.empty(3)
    wy = np.empty(3)
    dwy = np.empty(3)
    S = 2 if kind == 0 else 3
    ih = 1.0 / h
    for p in range(x.shape[0]):
        xi = (x[p, 0] - org0) * ih + PAD
        yi = (x[p, 1] - org1) * ih + PAD
        i0 = weights_1d(kind, xi, lp[p], wx, dwx)
        j0 = weights_1d(kind, yi, lp[p], wy, dwy)
        mp = m[p]
        Vp = vol[p]
        sxx, syy, sxy = s[p, 0], s[p, 1], s[p, 2]
        for a in range(S):
            for b in range(S):
                N = wx[a] * wy[b]
                if N == 0.0:
                    continue
                dNx = dwx[a] * wy[b] * ih
                dNy = wx[a] * dwy[b] * ih
                i, j = i0 + a, j0 + b
                vx, vy = v[p, 0], v[p, 1]
                if apic:
                    rx = (i - PAD) * h + org0 - x[p, 0]
                    ry = (j - PAD) * h + org1 - x[p, 1]
                    vx += C[p, 0, 0] * rx + C[p, 0, 1] * ry
                    vy += C[p, 1, 0] * rx + C[p, 1, 1] * ry
                gm[i, j] += N * mp
                gp[i, j, 0] += N * mp * vx
                gp[i, j, 1] += N * mp * vy
                gf[i, j, 0] += -Vp * (sxx * dNx + sxy * dNy) + N * (mp * g0 + fext[p, 0])
                gf[i, j, 1] += -Vp * (sxy * dNx + syy * dNy) + N * (mp * g1 + fext[p, 1])


@njit(cache=True)
def point_forces(kind, xb, fb, org0, org1, h, gm, gf):
    """Spread point loads of boundary particles onto the grid (boundary particles carry no mass). Only nodes
    holding mass receive force; the weights are renormalised over them so the total load is kept exactly."""
    wx = np.empty(3)
    dwx = np.empty(3)
    wy = np.empty(3)
    dwy = np.empty(3)
    S = 2 if kind == 0 else 3
    for p in range(xb.shape[0]):
        i0 = weights_1d(kind, (xb[p, 0] - org0) / h + PAD, 0.25, wx, dwx)
        j0 = weights_1d(kind, (xb[p, 1] - org1) / h + PAD, 0.25, wy, dwy)
        tot = 0.0
        for a in range(S):
            for b in range(S):
                if gm[i0 + a, j0 + b] > 1e-300:
                    tot += wx[a] * wy[b]
        if tot <= 0.0:
            continue
        for a in range(S):
            for b in range(S):
                if gm[i0 + a, j0 + b] > 1e-300:
                    N = wx[a] * wy[b] / tot
                    gf[i0 + a, j0 + b, 0] += N * fb[p, 0]
                    gf[i0 + a, j0 + b, 1] += N * fb[p, 1]


@njit(cache=True)
def apply_bc(gv, nx, ny, bc, mu):
    """Sides: 0 left, 1 right, 2 bottom, 3 top; bc 0 fixed, 1 slip, 2 friction, 3 open. Nodes on or beyond a
    side: the normal velocity into the wall is removed (separation allowed); friction reduces the tangential
    speed by mu |dv_n| (Coulomb, Bardenhagen et al. 2001); fixed sets both components to 0."""
    NX, NY = gv.shape[0], gv.shape[1]
    for side in range(4):
        k = bc[side]
        if k == 3:
            continue
        if side < 2:
            r0, r1 = (0, PAD + 1) if side == 0 else (PAD + nx, NX)
            for i in range(r0, r1):
                for j in range(NY):
                    _bc_node(gv, i, j, 0, 1.0 if side == 0 else -1.0, k, mu[side])
        else:
            r0, r1 = (0, PAD + 1) if side == 2 else (PAD + ny, NY)
            for i in range(NX):
                for j in range(r0, r1):
                    _bc_node(gv, i, j, 1, 1.0 if side == 2 else -1.0, k, mu[side])


@njit(cache=True, inline="always")
def _bc_node(gv, i, j, d, nrm, k, mu):
    if k == 0:
        gv[i, j, 0] = 0.0
        gv[i, j, 1] = 0.0
        return
    vn = gv[i, j, d] * nrm
    if vn < 0.0:
        gv[i, j, d] = 0.0
        if k == 2:
            t = 1 - d
            vt = gv[i, j, t]
            red = mu * (-vn)
            if abs(vt) <= red:
                gv[i, j, t] = 0.0
            else:
                gv[i, j, t] = vt - red * (1.0 if vt > 0 else -1.0)


@njit(cache=True)
def grid_update(gm, gp, gf, dt, gv0, gv1, nx, ny, bc, mu, alpha):
    """alpha: local non-viscous damping (Cundall 1987), f <- f - alpha |f| sign(v); 0 = none."""
    NX, NY = gm.shape[0], gm.shape[1]
    for i in range(NX):
        for j in range(NY):
            mm = gm[i, j]
            if mm > 1e-300:
                for d in range(2):
                    gv0[i, j, d] = gp[i, j, d] / mm
                    f = gf[i, j, d]
                    if alpha > 0.0 and gp[i, j, d] != 0.0:
                        f -= alpha * abs(f) * (1.0 if gp[i, j, d] > 0.0 else -1.0)
                    gv1[i, j, d] = (gp[i, j, d] + f * dt) / mm
            else:
                for d in range(2):
                    gv0[i, j, d] = 0.0
                    gv1[i, j, d] = 0.0
    apply_bc(gv0, nx, ny, bc, mu)
    apply_bc(gv1, nx, ny, bc, mu)


@njit(cache=True)
def g2p_range(lo, hi, kind, x, v, C, lp, org0, org1, h, dt, gv0, gv1, mode):
    """mode 0 USL / 1 MUSL: FLIP v += sum N (v1 - v0); 2 APIC: v = sum N v1, C = sum v1 (x) grad N.
    Positions x += dt sum N v1. Also stores L = sum v1 (x) grad N in C for USL (used by the stress update)."""
    wx = np.empty(3)
    dwx = np.empty(3)
    wy = np.empty(3)
    dwy = np.empty(3)
    S = 2 if kind == 0 else 3
    ih = 1.0 / h
    for p in range(lo, hi):
        i0 = weights_1d(kind, (x[p, 0] - org0) * ih + PAD, lp[p], wx, dwx)
        j0 = weights_1d(kind, (x[p, 1] - org1) * ih + PAD, lp[p], wy, dwy)
        px = py = dvx = dvy = 0.0
        l00 = l01 = l10 = l11 = 0.0
        for a in range(S):
            for b in range(S):
                N = wx[a] * wy[b]
                i, j = i0 + a, j0 + b
                ux, uy = gv1[i, j, 0], gv1[i, j, 1]
                px += N * ux
                py += N * uy
                dvx += N * (ux - gv0[i, j, 0])
                dvy += N * (uy - gv0[i, j, 1])
                dNx = dwx[a] * wy[b] * ih
                dNy = wx[a] * dwy[b] * ih
                l00 += ux * dNx
                l01 += ux * dNy
                l10 += uy * dNx
                l11 += uy * dNy
        if mode == 2:
            v[p, 0], v[p, 1] = px, py
        else:
            v[p, 0] += dvx
            v[p, 1] += dvy
        C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1] = l00, l01, l10, l11
        x[p, 0] += dt * px
        x[p, 1] += dt * py


@njit(cache=True)
def musl_gradient(kind, x, v, C, m, lp, org0, org1, h, gm, gp, gv, nx, ny, bc, mu):
    """MUSL: map updated particle momentum to the grid, apply BCs, store L = sum v_i (x) grad N_i in C."""
    gp[:] = 0.0
    wx = np.empty(3)
    dwx = np.empty(3)
    wy = np.empty(3)
    dwy = np.empty(3)
    S = 2 if kind == 0 else 3
    ih = 1.0 / h
    n = x.shape[0]
    for p in range(n):
        i0 = weights_1d(kind, (x[p, 0] - org0) * ih + PAD, lp[p], wx, dwx)
        j0 = weights_1d(kind, (x[p, 1] - org1) * ih + PAD, lp[p], wy, dwy)
        for a in range(S):
            for b in range(S):
                N = wx[a] * wy[b]
                gp[i0 + a, j0 + b, 0] += N * m[p] * v[p, 0]
                gp[i0 + a, j0 + b, 1] += N * m[p] * v[p, 1]
    NX, NY = gm.shape[0], gm.shape[1]
    for i in range(NX):
        for j in range(NY):
            if gm[i, j] > 1e-300:
                gv[i, j, 0] = gp[i, j, 0] / gm[i, j]
                gv[i, j, 1] = gp[i, j, 1] / gm[i, j]
            else:
                gv[i, j, 0] = 0.0
                gv[i, j, 1] = 0.0
    apply_bc(gv, nx, ny, bc, mu)
    for p in range(n):
        i0 = weights_1d(kind, (x[p, 0] - org0) * ih + PAD, lp[p], wx, dwx)
        j0 = weights_1d(kind, (x[p, 1] - org1) * ih + PAD, lp[p], wy, dwy)
        l00 = l01 = l10 = l11 = 0.0
        for a in range(S):
            for b in range(S):
                i, j = i0 + a, j0 + b
                dNx = dwx[a] * wy[b] * ih
                dNy = wx[a] * dwy[b] * ih
                l00 += gv[i, j, 0] * dNx
                l01 += gv[i, j, 0] * dNy
                l10 += gv[i, j, 1] * dNx
                l11 += gv[i, j, 1] * dNy
        C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1] = l00, l01, l10, l11


@njit(cache=True)
def stress_update_range(lo, hi, C, F, vol, vol0, s, eps_p, prm, mid, dt):
    """Points [lo, hi). Returns index of the first point with a non-finite stress, -1 if none."""
    de = np.empty(3)
    tmp = np.empty(8)
    for p in range(lo, hi):
        l00, l01, l10, l11 = C[p, 0, 0] * dt, C[p, 0, 1] * dt, C[p, 1, 0] * dt, C[p, 1, 1] * dt
        f00, f01, f10, f11 = F[p, 0], F[p, 1], F[p, 2], F[p, 3]
        F[p, 0] = f00 + l00 * f00 + l01 * f10
        F[p, 1] = f01 + l00 * f01 + l01 * f11
        F[p, 2] = f10 + l10 * f00 + l11 * f10
        F[p, 3] = f11 + l10 * f01 + l11 * f11
        vol[p] = vol0[p] * (F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2])
        de[0], de[1], de[2] = l00, l11, l01 + l10
        w = 0.5 * (l01 - l10)
        eps_p[p] = update_stress(prm[mid[p]], s[p], de, w, eps_p[p], tmp)
        if not (np.isfinite(s[p, 0]) and np.isfinite(s[p, 1]) and np.isfinite(s[p, 2])):
            return p
    return -1


@njit(cache=True)
def grid_velocity_at(kind, xb, org0, org1, h, gm, gv, out):
    """Grid velocity at boundary particles, weights renormalised over nodes holding mass (empty nodes carry no
    velocity)."""
    wx = np.empty(3)
    dwx = np.empty(3)
    wy = np.empty(3)
    dwy = np.empty(3)
    S = 2 if kind == 0 else 3
    for p in range(xb.shape[0]):
        i0 = weights_1d(kind, (xb[p, 0] - org0) / h + PAD, 0.25, wx, dwx)
        j0 = weights_1d(kind, (xb[p, 1] - org1) / h + PAD, 0.25, wy, dwy)
        ux = uy = tot = 0.0
        for a in range(S):
            for b in range(S):
                if gm[i0 + a, j0 + b] > 1e-300:
                    N = wx[a] * wy[b]
                    tot += N
                    ux += N * gv[i0 + a, j0 + b, 0]
                    uy += N * gv[i0 + a, j0 + b, 1]
        if tot > 0.0:
            out[p, 0], out[p, 1] = ux / tot, uy / tot
        else:
            out[p, 0], out[p, 1] = 0.0, 0.0


CHUNK = 1024


@njit(cache=True, parallel=True)
def g2p(kind, x, v, C, lp, org0, org1, h, dt, gv0, gv1, mode):
    """Particle-local gather: parallel over fixed chunks (results independent of the thread count)."""
    n = x.shape[0]
    nc = (n + CHUNK - 1) // CHUNK
    for c in prange(nc):
        g2p_range(c * CHUNK, min(n, (c + 1) * CHUNK), kind, x, v, C, lp, org0, org1, h, dt, gv0, gv1, mode)


@njit(cache=True, parallel=True)
def stress_update(C, F, vol, vol0, s, eps_p, prm, mid, dt):
    n = F.shape[0]
    nc = (n + CHUNK - 1) // CHUNK
    bad = np.full(nc, -1, np.int64)
    for c in prange(nc):
        bad[c] = stress_update_range(c * CHUNK, min(n, (c + 1) * CHUNK), C, F, vol, vol0, s, eps_p, prm, mid, dt)
    for c in range(nc):
        if bad[c] >= 0:
            return bad[c]
    return -1
