"""Compiled pieces of the implicit MPM step (numba): P2G of the Newmark state, the dof numbering and sparsity pattern
of the grid, the residual / consistent-tangent assembly (directly into the CSR arrays of the pattern), and the
update of the points after a converged step. Orchestration (Newton, line search, active sets, step cutting) is in
solver.py.

Grid node (i, j) of the padded grid (kernels.PAD ghost layers) has id i * NY + j; an active node (grid mass > 0)
has dofs 2 k (x) and 2 k + 1 (y), k = its rank among the active nodes by id. The pattern couples every active
node with the active nodes within W - 1 nodes in each direction (W = support width), so the CSR columns of a row
are sorted and the position of an entry is rowptr[row] + 2 slot[k, s] + c, s the stencil offset index.

Kinematics of one step (updated Lagrangian on the grid of the start of the step, as the explicit solver): nodal
displacement increment u, point displacement gradient L = sum_i u_i (x) grad N_i(x^n), strain increment sym(L),
spin W_xy dt = (L01 - L10) / 2, J = det(I + L); internal force f_i = sum_p V_p^n J sigma_p(L) . grad N_i(x^n)
(the current volume J V^n; gradients of the start configuration); sigma_p = law update from the stress of the
start of the step (state in, state out: nothing is committed until the step has converged).
"""
from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit, prange

from coupler.mpm.constitutive import stress_tangent, stress_update
from coupler.mpm.implicit import band_lu as BL
from coupler.mpm.kernels import NGROUP, PAD, _read, apic_d
from coupler.mpm.shapes import weights3


RESIDUAL, BOTH, TANGENT = 0, 1, 2     # assemble modes


@njit(cache=True)
def p2g(S, P, acc, W, G, A):
    """Mass, momentum (APIC: with the affine part), gravity + point external force into G (NX,NY,5: m, p, f);
    mass-weighted acceleration into A (NX,NY,2). Zeroes both first."""
    G[:] = 0.0
    A[:] = 0.0
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    apic = S.mode == 2
    x, v, C, m, lp = P.x, P.v, P.C, P.m, P.lp
    for p in range(x.shape[0]):
        xp, yp = x[p, 0], x[p, 1]
        i0, wx, _ = weights3(S.kind, (xp - S.org0) * ih + PAD, lp[p], PAD, hx)
        j0, wy, _ = weights3(S.kind, (yp - S.org1) * ih + PAD, lp[p], PAD, hy)
        mp = m[p]
        bx = mp * S.g0 + P.fext[p, 0]
        by = mp * S.g1 + P.fext[p, 1]
        rx0 = (i0 - PAD) * S.h + S.org0 - xp
        ry0 = (j0 - PAD) * S.h + S.org1 - yp
        for a in range(W):
            for b in range(W):
                N = wx[a] * wy[b]
                if N == 0.0:
                    continue
                ux, uy = v[p, 0], v[p, 1]
                if apic:
                    rx = rx0 + a * S.h
                    ry = ry0 + b * S.h
                    ux += C[p, 0, 0] * rx + C[p, 0, 1] * ry
                    uy += C[p, 1, 0] * rx + C[p, 1, 1] * ry
                i, j = i0 + a, j0 + b
                Nm = N * mp
                G[i, j, 0] += Nm
                G[i, j, 1] += Nm * ux
                G[i, j, 2] += Nm * uy
                G[i, j, 3] += N * bx
                G[i, j, 4] += N * by
                A[i, j, 0] += Nm * acc[p, 0]
                A[i, j, 1] += Nm * acc[p, 1]


@njit(cache=True)
def active_nodes(G):
    """Ids (i * NY + j, ascending) of the nodes with mass (m > 1e-300): the active nodes that carry dofs."""
    NX, NY = G.shape[0], G.shape[1]
    n = 0
    for i in range(NX):
        for j in range(NY):
            if G[i, j, 0] > 1e-300:
                n += 1
    act = np.empty(n, np.int64)
    n = 0
    for i in range(NX):
        for j in range(NY):
            if G[i, j, 0] > 1e-300:
                act[n] = i * NY + j
                n += 1
    return act


@njit(cache=True)
def number_dofs(NX, NY, act, W):
    """For the active nodes act (active_nodes, ids ascending): node_dof (NX*NY,) = 2 k for active node of rank k, -1
    otherwise; the CSR pattern (rowptr, cols), slot (nact, (2W-1)^2) and diag (ndof,) positions. Returns
    (node_dof, rowptr, cols, slot, diag)."""
    nact = act.shape[0]
    node_dof = np.full(NX * NY, -1, np.int64)
    for k in range(nact):
        node_dof[act[k]] = 2 * k
    SW = 2 * W - 1
    slot = np.full((nact, SW * SW), -1, np.int64)
    cnt = np.zeros(nact, np.int64)
    for k in range(nact):
        i, j = act[k] // NY, act[k] % NY
        c = 0
        for di in range(-(W - 1), W):
            ii = i + di
            if ii < 0 or ii >= NX:
                continue
            for dj in range(-(W - 1), W):
                jj = j + dj
                if jj < 0 or jj >= NY:
                    continue
                if node_dof[ii * NY + jj] >= 0:
                    slot[k, (di + W - 1) * SW + dj + W - 1] = c
                    c += 1
        cnt[k] = c
    ndof = 2 * nact
    rowptr = np.zeros(ndof + 1, np.int64)
    for k in range(nact):
        rowptr[2 * k + 1] = rowptr[2 * k] + 2 * cnt[k]
        rowptr[2 * k + 2] = rowptr[2 * k + 1] + 2 * cnt[k]
    cols = np.empty(rowptr[ndof], np.int64)
    diag = np.empty(ndof, np.int64)
    for k in range(nact):
        n = act[k]
        i, j = n // NY, n % NY
        for r in range(2):
            q = rowptr[2 * k + r]
            for di in range(-(W - 1), W):
                ii = i + di
                if ii < 0 or ii >= NX:
                    continue
                for dj in range(-(W - 1), W):
                    jj = j + dj
                    if jj < 0 or jj >= NY:
                        continue
                    d = node_dof[ii * NY + jj]
                    if d >= 0:
                        if d == 2 * k:
                            diag[2 * k + r] = q + r
                        cols[q] = d
                        cols[q + 1] = d + 1
                        q += 2
    return node_dof, rowptr, cols, slot, diag


@njit(cache=True)
def grid_fields(G, A, act):
    """Per dof of the active nodes act (dofs 2 k, 2 k + 1 of node act[k]): lumped mass, velocity p / m, acceleration
    (mass-weighted sum) / m and external force of the P2G fields G (NX, NY, 5: m, p, f) and A (NX, NY, 2)."""
    NY = G.shape[1]
    n = act.shape[0]
    mass, vn0, an0, fext = np.empty(2 * n), np.empty(2 * n), np.empty(2 * n), np.empty(2 * n)
    for k in range(n):
        i, j = act[k] // NY, act[k] % NY
        m = G[i, j, 0]
        for c in range(2):
            mass[2 * k + c] = m
            vn0[2 * k + c] = G[i, j, 1 + c] / m
            an0[2 * k + c] = A[i, j, c] / m
            fext[2 * k + c] = G[i, j, 3 + c]
    return mass, vn0, an0, fext


@njit(cache=True, inline="always")
def _newmark(u, vn, an, c_m, dt, k_a, gamma):
    """Newmark's end-of-step acceleration and velocity of displacement increment u: a1 = c_m (u - dt vn) - k_a an,
    v1 = vn + dt ((1 - gamma) an + gamma a1) (c_m = 1 / (beta dt^2), k_a = 1 / (2 beta) - 1)."""
    a1 = c_m * (u - dt * vn) - k_a * an
    return a1, vn + dt * ((1.0 - gamma) * an + gamma * a1)


@njit(cache=True)
def inertia_residual(u, vn, an, mass, fext, fint, c_m, dt, k_a, R):
    """R = m a1 - f_ext + f_int with the Newmark acceleration a1 = c_m (u - dt vn) - k_a an (c_m = 1 / (beta dt^2),
    k_a = 1 / (2 beta) - 1) of the displacement increment u."""
    for i in range(u.shape[0]):
        a1 = c_m * (u[i] - dt * vn[i]) - k_a * an[i]       # (_newmark's a1; v1 not needed)
        R[i] = mass[i] * a1 - fext[i] + fint[i]


@njit(cache=True)
def free_norm(r, held):
    """Euclidean norm of r over the dofs not held (the gathered entries' dot product, as numpy's norm)."""
    buf = np.empty(r.shape[0])
    n = 0
    for i in range(r.shape[0]):
        if not held[i]:
            buf[n] = r[i]
            n += 1
    b = buf[:n]
    return math.sqrt(np.dot(b, b))


@njit(cache=True)
def predictor(code, vn0, an0, dt, half_dt2):
    """Start of a step: held = code > 0 (every wall dof starts held), the velocity / acceleration of the step start
    (vn, an: 0 on held dofs) and the predicted displacement increment u = dt vn + dt^2 / 2 an (the Newmark predictor
    with a^{n+1} = a^n; 0 on held dofs)."""
    n = code.shape[0]
    held = np.empty(n, np.bool_)
    vn, an, u = vn0.copy(), an0.copy(), np.empty(n)
    for i in range(n):
        held[i] = code[i] > 0
        if held[i]:
            vn[i] = 0.0
            an[i] = 0.0
        u[i] = 0.0 if held[i] else dt * vn[i] + half_dt2 * an[i]
    return held, vn, an, u


@njit(cache=True)
def newmark_end(u, vn, an, held, c_m, dt, k_a, gamma):
    """a1 = c_m (u - dt vn) - k_a an, v1 = vn + dt ((1 - gamma) an + gamma a1) (Newmark), 0 on held dofs."""
    n = u.shape[0]
    a1, v1 = np.empty(n), np.empty(n)
    for i in range(n):
        a, v = _newmark(u[i], vn[i], an[i], c_m, dt, k_a, gamma)
        v1[i] = 0.0 if held[i] else v
        a1[i] = 0.0 if held[i] else a
    return a1, v1


@njit(cache=True)
def normal_tests(nrm, held, r, u, nin, tol, eps):
    """Unilateral wall normals (nrm): (held ones the wall pulls, r n_in < -tol; released ones moved into the wall,
    u n_in < eps, and whether each has any)."""
    n = r.shape[0]
    rel, back = np.zeros(n, np.bool_), np.zeros(n, np.bool_)
    for i in range(n):
        if nrm[i]:
            if held[i]:
                rel[i] = r[i] * nin[i] < -tol
            else:
                back[i] = u[i] * nin[i] < eps
    return rel, back, rel.any(), back.any()


@njit(cache=True, inline="always")
def _wall_normal_force(held, r, nin, n):
    """N of a node's wall-normal dof n: its reaction r n_in where held and pushing (np.maximum's NaN kept), else 0."""
    if not held[n]:
        return 0.0
    v = r[n] * nin[n]
    return v if (v > 0.0 or v != v) else 0.0


@njit(cache=True)
def friction_residual(R, fr, held, nin, mu, fsign):
    """R_t -= mu N s on the sliding Coulomb dofs t (fr and not held): N the reaction of the node's held normal dof
    t ^ 1 (evaluated before any R_t changes), s = fsign the friction direction."""
    n = R.shape[0]
    N = np.zeros(n)
    for t in range(n):
        if fr[t] and not held[t]:
            N[t] = _wall_normal_force(held, R, nin, t ^ 1)
    for t in range(n):
        if fr[t] and not held[t]:
            R[t] -= mu[t] * N[t] * fsign[t]


@njit(cache=True)
def friction_tests(fr, held, code, r, u, vn, an, nin, mu, fsign, c_m, dt, k_a, gamma, tol):
    """Coulomb dofs: (stuck ones beyond mu N + tol, N the reaction of the node's held normal dof (on a wall dof);
    sliding ones whose Newmark end velocity turned against their friction force, v1 s > 0; and whether each has
    any)."""
    n = r.shape[0]
    beyond, reversed_ = np.zeros(n, np.bool_), np.zeros(n, np.bool_)
    for t in range(n):
        if not fr[t]:
            continue
        if held[t]:
            N = _wall_normal_force(held, r, nin, t ^ 1) if code[t ^ 1] > 0 else 0.0
            beyond[t] = abs(r[t]) > mu[t] * N + tol
        else:
            _, v1 = _newmark(u[t], vn[t], an[t], c_m, dt, k_a, gamma)
            reversed_[t] = v1 * fsign[t] > 0.0
    return beyond, reversed_, beyond.any(), reversed_.any()


@njit(cache=True)
def slide_rows(fr, held, r, nin, mu, fsign):
    """The sliding-friction rows of the Newton matrix (kernels.to_band): slide_n[t] = the node's held normal dof n =
    t ^ 1 where t slides and n pushes (r n_in > 0), else -1; slide_c[t] = mu s n_in."""
    m = r.shape[0]
    slide_n = np.full(m, -1, np.int64)
    slide_c = np.zeros(m)
    for t in range(m):
        if fr[t] and not held[t]:
            n = t ^ 1
            if held[n] and r[n] * nin[n] > 0.0:
                slide_n[t] = n
                slide_c[t] = mu[t] * fsign[t] * nin[n]
    return slide_n, slide_c


@njit(cache=True)
def same(a, b):
    """a == b elementwise everywhere (NaN differs; np.array_equal of two equal-length vectors, without its ~3 us)."""
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


@njit(cache=True)
def volume_ratio_range(L):
    """(min, argmin, max, argmax) over the points of the step's volume ratio det(I + L), L = grad u (the F update
    of commit: F <- (I + L) F, so vol <- det(I + L) vol)."""
    lo, hi, plo, phi = np.inf, -np.inf, -1, -1
    for p in range(L.shape[0]):
        j = (1.0 + L[p, 0]) * (1.0 + L[p, 3]) - L[p, 1] * L[p, 2]
        if j < lo:
            lo, plo = j, p
        if j > hi:
            hi, phi = j, p
    return lo, plo, hi, phi


@njit(cache=True)
def plastic_flips(dep, was):
    """Points whose plastic state (dep > 0) differs from was; was updated to it."""
    c = 0
    for p in range(dep.shape[0]):
        now = dep[p] > 0.0
        if now != was[p]:
            c += 1
            was[p] = now
    return c


@njit(cache=True)
def all_finite(x):
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(cache=True)
def dof_grids(NX, NY, act, u, v0, v1, a1):
    """(4, NX, NY, 2) grid fields u, v0, v1, a1 from their dof vectors (zero at the nodes without mass)."""
    g = np.zeros((4, NX, NY, 2))
    for k in range(act.shape[0]):
        i, j = act[k] // NY, act[k] % NY
        for c in range(2):
            g[0, i, j, c] = u[2 * k + c]
            g[1, i, j, c] = v0[2 * k + c]
            g[2, i, j, c] = v1[2 * k + c]
            g[3, i, j, c] = a1[2 * k + c]
    return g


@njit(cache=True)
def stencil_groups(S, P, NY):
    """Points grouped by their support stencil (first node i0, j0; every point of a group couples the same nodes):
    (order, gstart, key): the points of group g are order[gstart[g]:gstart[g + 1]], groups in node-id order (key[g]
    = the id i0 NY + j0 of their first node, ascending) and the points of a group in index order (a counting sort by
    node id: stable, deterministic, O(points + nodes)). assemble sums each group's tangent locally and scatters it
    into the CSR arrays once."""
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    n = P.x.shape[0]
    nkey = (S.nx + 1 + 2 * PAD) * NY
    key = np.empty(n, np.int64)
    count = np.zeros(nkey + 1, np.int64)
    for p in range(n):
        i0, _, _ = weights3(S.kind, (P.x[p, 0] - S.org0) * ih + PAD, P.lp[p], PAD, hx)
        j0, _, _ = weights3(S.kind, (P.x[p, 1] - S.org1) * ih + PAD, P.lp[p], PAD, hy)
        key[p] = i0 * NY + j0
        count[key[p] + 1] += 1
    ng = 0
    for k in range(nkey):
        if count[k + 1] > 0:
            ng += 1
        count[k + 1] += count[k]            # count[k] = first slot of key k
    gstart = np.empty(ng + 1, np.int64)
    gkey = np.empty(ng, np.int64)
    g = 0
    for k in range(nkey):
        if count[k + 1] > count[k]:
            gstart[g] = count[k]
            gkey[g] = k
            g += 1
    gstart[ng] = n
    order = np.empty(n, np.int64)
    for p in range(n):
        order[count[key[p]]] = p
        count[key[p]] += 1
    return order, gstart, gkey


Pattern = namedtuple("Pattern", ["node_dof", "slot", "rowptr", "act"])
Pattern.__doc__ = """Dof numbering and CSR pattern of a step (number_dofs): node_dof (NX*NY,), slot (nact, (2W-1)^2),
rowptr (ndof + 1,), act (nact,) the active node ids (ascending; dof rows 2 k, 2 k + 1 are node act[k])."""
Groups = namedtuple("Groups", ["order", "start", "key", "dofs", "Kx", "Ky", "f", "ok"])
Groups.__doc__ = """Points by support stencil (stencil_groups: order, start, key) and assemble's per-group results
between its two passes: dofs (ng, 9) the stencil's dofs (-1: no dof), Kx, Ky (ng, 18, 9) the group's tangent block
K[(q a), (q2 x|y)], f (n, 18) each point's internal force on its stencil dofs (by position in order), ok (n,) its
stress finite."""
Trial = namedtuple("Trial", ["s", "dep", "L"])
Trial.__doc__ = """Trial state of the last evaluated displacement increment, per point: s (n, 4) stress, dep (n,)
plastic strain increment, L (n, 4) displacement gradient (L00, L01, L10, L11)."""


def groups(S, P, NY, serial: bool) -> Groups:
    """The stencil groups of the points at the start of a step, with assemble's work arrays (written before they
    are read; serial: the one-pass assembly, which needs no per-group blocks or per-point forces)."""
    order, start, key = stencil_groups(S, P, NY)
    ng, n = (1, 1) if serial else (len(key), len(order))
    return Groups(order, start, key, np.full((len(key), 9), -1, np.int64), np.empty((ng, 18, 9)),
                  np.empty((ng, 18, 9)), np.empty((n, 18)), np.ones(len(order), np.bool_))


@njit(cache=True)
def half_bandwidth(rowptr, cols):
    """max |i - j| over the CSR entries (row i, column j); 0 for an empty matrix."""
    bw = 0
    for i in range(rowptr.shape[0] - 1):
        for k in range(rowptr[i], rowptr[i + 1]):
            bw = max(bw, abs(i - cols[k]))
    return bw


@njit(cache=True, parallel=True)
def assemble(S, P, W, pat, grp, u, dt, mode, data, R, trial, bad, serial):
    """mode RESIDUAL: R += internal force of the displacement increment u (dofs), the per-point trial state into
    trial (Trial); mode BOTH: that and data += the consistent tangent of the internal force (mass term added by the
    caller: data[diag] += mass / (beta dt^2)); mode TANGENT: the tangent alone at the u of the last evaluation, from
    its trial state (R and trial not written): the same numbers as BOTH without the stress update and force scatter
    again (the Newton step after a residual-only trial point). Points in the groups of stencil_groups (grp): a
    group's tangent is summed in a local (2 W^2)^2 block and scattered once (the CSR scatter, ~324 indexed updates
    per point, was most of the assembly). bad[0] = first point (by index) with a non-finite stress or -1.
    Two parallel passes, each over NGROUP shares that prange deals out to the threads: (1) the groups, in shares
    of about equal point counts: stress updates, the points' forces and the groups' blocks into grp; (2) the dof
    rows, in shares of about equal CSR entries: for the groups that touch its rows, in group order, a share adds
    their forces to R and their blocks to data.
    Every sum is then formed in the order of a serial pass over the groups: the result is bitwise the same for any
    thread count, and as the serial assembly it replaced (twenty-second session). serial (the caller runs one numba
    thread): one pass that scatters each group as it is summed (its block in cache, no per-group arrays: the two
    passes cost 6-8 % more on one thread, h = 5 mm), the same sums in the same order.
    The body is compiled once per stencil width (W = 2 linear / 3 quadratic and uGIMP), so its small loops over
    the W^2 stencil nodes have constant trip counts (unrolled, vectorised); the result is the same for any W.
    The work arrays hold MAX_WIDTH^2 = 9 stencil nodes: another width is an error, not an out-of-bounds write."""
    if W != 2 and W != 3:
        raise ValueError("implicit assemble: stencil width must be 2 or 3 (compiled widths; scratch for 3 x 3 nodes)")
    n = grp.order.shape[0]
    ng = grp.key.shape[0]
    if serial:
        if W == 3:
            bad[0] = _groups_w3(S, P, pat, grp, 0, ng, u, dt, mode, trial, True, data, R)
        else:
            bad[0] = _groups_w2(S, P, pat, grp, 0, ng, u, dt, mode, trial, True, data, R)
        return
    nt = max(1, min(NGROUP, n // 64))
    badc = np.full(nt, -1, np.int64)
    for t in prange(nt):
        g0 = np.searchsorted(grp.start, (n * t) // nt)
        g1 = np.searchsorted(grp.start, (n * (t + 1)) // nt) if t < nt - 1 else ng
        if W == 3:
            badc[t] = _groups_w3(S, P, pat, grp, g0, g1, u, dt, mode, trial, False, data, R)
        else:
            badc[t] = _groups_w2(S, P, pat, grp, g0, g1, u, dt, mode, trial, False, data, R)
    b = -1
    for t in range(nt):
        if badc[t] >= 0 and (b < 0 or badc[t] < b):
            b = badc[t]
    bad[0] = b
    ndof = R.shape[0]
    nr = max(1, min(NGROUP, ndof // 64))
    for t in prange(nr):
        lo = _row_split(pat.rowptr, t, nr)
        hi = _row_split(pat.rowptr, t + 1, nr)
        if W == 3:
            _scatter_rows(S, 3, pat, grp, mode, data, R, lo, hi)
        else:
            _scatter_rows(S, 2, pat, grp, mode, data, R, lo, hi)


@njit(cache=True, inline="always")
def _row_split(rowptr, t, nt):
    """First dof row of share t of nt (shares of about equal CSR entries, at node boundaries: even rows)."""
    ndof = rowptr.shape[0] - 1
    if t >= nt:
        return ndof
    d = np.searchsorted(rowptr, (rowptr[ndof] * t) // nt)
    return min(d - d % 2, ndof)


@njit(cache=True)
def _groups_w3(S, P, pat, grp, g0, g1, u, dt, mode, trial, fused, data, R):
    return _groups(S, P, 3, pat, grp, g0, g1, u, dt, mode, trial, fused, data, R)


@njit(cache=True)
def _groups_w2(S, P, pat, grp, g0, g1, u, dt, mode, trial, fused, data, R):
    return _groups(S, P, 2, pat, grp, g0, g1, u, dt, mode, trial, fused, data, R)


@njit(cache=True, inline="always")
def _groups(S, P, W, pat, grp, g0, g1, u, dt, mode, trial, fused, data, R):
    """assemble's first pass over groups g0 .. g1 - 1 with W a constant where inlined: per point the stress update
    (fresh modes) into trial and its force on the stencil dofs into grp.f (grp.ok: finite), per group the tangent
    block into grp.Kx, grp.Ky and the stencil dofs into grp.dofs. fused: the forces straight into R and each block
    into data once summed (the serial assembly; the block in this call's scratch). Stencil node (a, b) has the fixed
    slot q = a W + b; a node without a dof (dof -1, no mass) has zero gradients in the block. Returns the first point
    (by index) with a non-finite stress, or -1. Its scratch arrays are this call's own (one call per share)."""
    NY = S.ny + 1 + 2 * PAD
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    NN = W * W
    x, lp, s, vol = P.x, P.lp, P.s, P.vol
    s_new, dep_new, L_new = trial.s, trial.dep, trial.L
    order, gstart, f, ok = grp.order, grp.start, grp.f, grp.ok
    node_dof = pat.node_dof
    ndof = R.shape[0]
    Kl = np.zeros((18, 9))
    Kyl = np.zeros((18, 9))
    T = np.empty((4, 4))
    D = np.empty((4, 4))
    gx = np.empty(9)
    gy = np.empty(9)
    Q = np.empty((9, 2, 4))
    want_K = mode != RESIDUAL
    fresh = mode != TANGENT       # a new trial state (else the stored one of this u)
    bad = -1
    for g in range(g0, g1):
        dofs = grp.dofs[g]
        if fused:      # K[(q a), (q2 x)] and K[(q a), (q2 y)]: contiguous in q2 (SIMD)
            Kx, Ky = Kl, Kyl
        else:
            Kx, Ky = grp.Kx[g], grp.Ky[g]
        if want_K:
            Kx[:] = 0.0
            Ky[:] = 0.0
        for k in range(gstart[g], gstart[g + 1]):
            p = order[k]
            xp, yp = x[p, 0], x[p, 1]
            i0, wx, dwx = weights3(S.kind, (xp - S.org0) * ih + PAD, lp[p], PAD, hx)
            j0, wy, dwy = weights3(S.kind, (yp - S.org1) * ih + PAD, lp[p], PAD, hy)
            l00 = l01 = l10 = l11 = 0.0
            if not fresh:
                l00, l01, l10, l11 = L_new[p, 0], L_new[p, 1], L_new[p, 2], L_new[p, 3]
            for a in range(W):
                for b in range(W):
                    q = a * W + b
                    d = node_dof[(i0 + a) * NY + j0 + b]
                    dofs[q] = d
                    if d < 0:
                        gx[q] = 0.0
                        gy[q] = 0.0
                        continue
                    dNx = dwx[a] * wy[b] * ih
                    dNy = wx[a] * dwy[b] * ih
                    gx[q], gy[q] = dNx, dNy
                    if not fresh:
                        continue
                    ux, uy = u[d], u[d + 1]
                    l00 += ux * dNx
                    l01 += ux * dNy
                    l10 += uy * dNx
                    l11 += uy * dNy
            prm = S.prm[P.mid[p]]
            gxy = l01 + l10
            w = 0.5 * (l01 - l10)
            J = (1.0 + l00) * (1.0 + l11) - l01 * l10
            V = vol[p]
            if fresh:
                r = stress_update(prm, s[p, 0], s[p, 1], s[p, 2], s[p, 3], l00, l11, gxy, w, dt)
                if not (np.isfinite(r[0]) and np.isfinite(r[1]) and np.isfinite(r[2]) and np.isfinite(r[3])):
                    ok[k] = False
                    if bad < 0 or p < bad:
                        bad = p
                    continue
                ok[k] = True
                s_new[p, 0], s_new[p, 1], s_new[p, 2], s_new[p, 3] = r[0], r[1], r[2], r[3]
                dep_new[p] = r[4]
                L_new[p, 0], L_new[p, 1], L_new[p, 2], L_new[p, 3] = l00, l01, l10, l11
                sxx, syy, sxy = r[0] * J * V, r[1] * J * V, r[2] * J * V
                for q in range(NN):
                    if fused:
                        d = dofs[q]
                        if d >= 0:
                            R[d] += sxx * gx[q] + sxy * gy[q]
                            R[d + 1] += sxy * gx[q] + syy * gy[q]
                    else:
                        f[k, 2 * q] = sxx * gx[q] + sxy * gy[q]
                        f[k, 2 * q + 1] = sxy * gx[q] + syy * gy[q]
                if not want_K:
                    continue
            else:
                r = (s_new[p, 0], s_new[p, 1], s_new[p, 2], s_new[p, 3], dep_new[p])
            stress_tangent(prm, s[p, 0], s[p, 1], s[p, 2], s[p, 3], l00, l11, gxy, w, dt, T)
            # D[ab, cd] = d (J sigma_ab) / d L_cd, ab and cd over (00, 01, 10, 11); sigma rows xx, yy, xy
            dJ0, dJ1, dJ2, dJ3 = 1.0 + l11, -l10, -l01, 1.0 + l00
            for k2 in range(4):
                # d sigma / d L_cd for cd = 00, 01, 10, 11
                if k2 == 0:
                    cx, cy, cz = T[0, 0], T[1, 0], T[2, 0]
                    dJ = dJ0
                elif k2 == 1:
                    cx, cy, cz = T[0, 2] + 0.5 * T[0, 3], T[1, 2] + 0.5 * T[1, 3], T[2, 2] + 0.5 * T[2, 3]
                    dJ = dJ1
                elif k2 == 2:
                    cx, cy, cz = T[0, 2] - 0.5 * T[0, 3], T[1, 2] - 0.5 * T[1, 3], T[2, 2] - 0.5 * T[2, 3]
                    dJ = dJ2
                else:
                    cx, cy, cz = T[0, 1], T[1, 1], T[2, 1]
                    dJ = dJ3
                D[0, k2] = V * (r[0] * dJ + J * cx)     # ab = 00 (xx)
                D[1, k2] = V * (r[2] * dJ + J * cz)     # 01 (xy)
                D[2, k2] = V * (r[2] * dJ + J * cz)     # 10 (yx)
                D[3, k2] = V * (r[1] * dJ + J * cy)     # 11 (yy)
            # Q[q, a, cd] = sum_b dN_q/dx_b D[ab, cd]
            for q in range(NN):
                for k2 in range(4):
                    Q[q, 0, k2] = gx[q] * D[0, k2] + gy[q] * D[1, k2]
                    Q[q, 1, k2] = gx[q] * D[2, k2] + gy[q] * D[3, k2]
            # K[(q a), (q2 c)] = sum_d Q[q, a, cd] dN_q2/dx_d, summed over the group's points
            for q in range(NN):
                for a in range(2):
                    qa = 2 * q + a
                    q0, q1, q2_, q3 = Q[q, a, 0], Q[q, a, 1], Q[q, a, 2], Q[q, a, 3]
                    kx, ky = Kx[qa], Ky[qa]
                    for q2 in range(NN):
                        kx[q2] += q0 * gx[q2] + q1 * gy[q2]
                        ky[q2] += q2_ * gx[q2] + q3 * gy[q2]
        if fused and want_K and gstart[g + 1] > gstart[g]:
            _scatter_block(W, pat, dofs, Kx, Ky, data, 0, ndof)
    return bad


@njit(cache=True, inline="always")
def _scatter_rows(S, W, pat, grp, mode, data, R, lo, hi):
    """assemble's second pass for dof rows lo .. hi - 1 (even bounds): the forces of the groups' points into R
    (fresh modes) and the groups' blocks into data (tangent modes), over the groups that touch these rows (keys from
    that of the rows' first node minus (W - 1) (NY + 1) to that of their last), in group order and within a group in
    point order: each entry gets its terms in the order of a serial pass."""
    if lo >= hi:
        return
    NY = S.ny + 1 + 2 * PAD
    NN = W * W
    act = pat.act
    gstart, f, ok = grp.start, grp.f, grp.ok
    want_K = mode != RESIDUAL
    fresh = mode != TANGENT
    g_lo = np.searchsorted(grp.key, act[lo // 2] - (W - 1) * (NY + 1))
    g_hi = np.searchsorted(grp.key, act[(hi - 1) // 2], side="right")
    for g in range(g_lo, g_hi):
        dofs = grp.dofs[g]
        if fresh:
            for k in range(gstart[g], gstart[g + 1]):
                if not ok[k]:
                    continue
                for q in range(NN):
                    d = dofs[q]
                    if d >= lo and d < hi:
                        R[d] += f[k, 2 * q]
                        R[d + 1] += f[k, 2 * q + 1]
        if want_K and gstart[g + 1] > gstart[g]:
            _scatter_block(W, pat, dofs, grp.Kx[g], grp.Ky[g], data, lo, hi)


@njit(cache=True, inline="always")
def _scatter_block(W, pat, dofs, Kx, Ky, data, lo, hi):
    """A group's block (Kx, Ky: K[(q a), (q2 x|y)]) into the CSR values data, rows lo .. hi - 1. The CSR slot of node
    pair (q, q2) follows from their stencil offsets q2 // W - q // W, q2 % W - q % W."""
    SW = 2 * W - 1
    NN = W * W
    slot, rowptr = pat.slot, pat.rowptr
    for q in range(NN):
        dq = dofs[q]
        if dq < lo or dq >= hi:
            continue
        kq = dq // 2
        for q2 in range(NN):
            if dofs[q2] < 0:
                continue
            s_ix = (q2 // W - q // W + W - 1) * SW + q2 % W - q % W + W - 1
            base = 2 * slot[kq, s_ix]
            for a in range(2):
                pos = rowptr[dq + a] + base
                data[pos] += Kx[2 * q + a, q2]
                data[pos + 1] += Ky[2 * q + a, q2]


@njit(cache=True, inline="always")
def _grad_column(V1, i0, j0, W, ax, by, ih):
    """sum_ab V1[i0 + a, j0 + b] ax[a] by[b] ih: a column of grad v (ax, by = (dwx, wy) or (wx, dwy))."""
    gx = gy = 0.0
    for a in range(W):
        for b in range(W):
            g = ax[a] * by[b] * ih
            gx += V1[i0 + a, j0 + b, 0] * g
            gy += V1[i0 + a, j0 + b, 1] * g
    return gx, gy


@njit(cache=True)
def commit(S, P, W, node_dof, U, V0, V1, A1, s_new, dep_new, L_new, flip, acc):
    """After convergence: x += sum N u_i, v (FLIP: += sum N (v1 - v0), C not written (not read); APIC: = sum N v1,
    C = B D^-1 as the explicit gather, kernels._gather_range: B = sum N v1 r^T, D = h^2/4 I for the quadratic
    B-spline, D(x_p) otherwise), acceleration = sum N a1, stress / eps_p from the trial state, F = (I + L) F,
    vol = vol0 det F, acc = sum N a1 (the acceleration at the position of the start of the step: Newmark's a^{n+1}
    of the point). Returns the first point with a new position outside S.box or -1. U, V0, V1, A1: (NX, NY, 2)
    grid fields."""
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    x, v, C, F, s, vol, vol0, eps_p, lp = P.x, P.v, P.C, P.F, P.s, P.vol, P.vol0, P.eps_p, P.lp
    box = S.box
    out = -1
    for p in range(x.shape[0]):
        xp, yp = x[p, 0], x[p, 1]
        xi, eta = (xp - S.org0) * ih + PAD, (yp - S.org1) * ih + PAD
        i0, wx, dwx = weights3(S.kind, xi, lp[p], PAD, hx)
        j0, wy, dwy = weights3(S.kind, eta, lp[p], PAD, hy)
        dx = dy = vx = vy = dvx = dvy = ax = ay = 0.0
        c00 = c01 = c10 = c11 = 0.0
        dxx = dyy = 0.0
        if not flip:
            dxx, dyy = apic_d(S.kind, W, i0, j0, xi, eta, wx, wy)
        for a in range(W):
            for b in range(W):
                i, j = i0 + a, j0 + b
                N = wx[a] * wy[b]
                dx += N * U[i, j, 0]
                dy += N * U[i, j, 1]
                vx += N * V1[i, j, 0]
                vy += N * V1[i, j, 1]
                dvx += N * (V1[i, j, 0] - V0[i, j, 0])
                dvy += N * (V1[i, j, 1] - V0[i, j, 1])
                ax += N * A1[i, j, 0]
                ay += N * A1[i, j, 1]
                if not flip:
                    Nrx = N * (i0 + a - xi)
                    Nry = N * (j0 + b - eta)
                    c00 += V1[i, j, 0] * Nrx
                    c01 += V1[i, j, 0] * Nry
                    c10 += V1[i, j, 1] * Nrx
                    c11 += V1[i, j, 1] * Nry
        if flip:
            v[p, 0] += dvx
            v[p, 1] += dvy
        else:
            v[p, 0], v[p, 1] = vx, vy
            # C = B D^-1; D_xx = 0 only for linear weights with the point on a node line: the limit, dv/dx
            if dxx > 0.0:
                C[p, 0, 0], C[p, 1, 0] = c00 * ih / dxx, c10 * ih / dxx
            else:
                C[p, 0, 0], C[p, 1, 0] = _grad_column(V1, i0, j0, W, dwx, wy, ih)
            if dyy > 0.0:
                C[p, 0, 1], C[p, 1, 1] = c01 * ih / dyy, c11 * ih / dyy
            else:
                C[p, 0, 1], C[p, 1, 1] = _grad_column(V1, i0, j0, W, wx, dwy, ih)
        acc[p, 0], acc[p, 1] = ax, ay
        xn, yn = xp + dx, yp + dy
        x[p, 0], x[p, 1] = xn, yn
        l00, l01, l10, l11 = L_new[p, 0], L_new[p, 1], L_new[p, 2], L_new[p, 3]
        f00, f01, f10, f11 = F[p, 0], F[p, 1], F[p, 2], F[p, 3]
        F[p, 0] = f00 + l00 * f00 + l01 * f10
        F[p, 1] = f01 + l00 * f01 + l01 * f11
        F[p, 2] = f10 + l10 * f00 + l11 * f10
        F[p, 3] = f11 + l10 * f01 + l11 * f11
        vol[p] = vol0[p] * (F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2])
        s[p, 0], s[p, 1], s[p, 2], s[p, 3] = s_new[p, 0], s_new[p, 1], s_new[p, 2], s_new[p, 3]
        eps_p[p] += dep_new[p]
        if out < 0 and not (xn >= box[0] and xn <= box[2] and yn >= box[1] and yn <= box[3]):
            out = p
    return out


@njit(cache=True)
def move_boundary(S, B, G, W, U, V1):
    """Boundary particles: x += sum N u_i, v = sum N v1_i with the explicit solver's transfer weights
    (kernels._read / kernels._transfer: renormalised over the nodes holding mass, sliver nodes by their momentum, the
    part a support of slivers cannot carry read from the nearest full nodes; the transpose of kernels.spread_loads);
    a particle attached to a wall side keeps its normal coordinate (normal displacement and velocity 0; both 0 on a
    fixed side). A particle no node of whose support or reroute window holds mass is stranded: it does not move;
    counted in B.drop[4] (particle-steps) and B.drop[5] (most in one step), as the explicit kernel."""
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    xb, mcs = B.x, B.mc
    stranded = 0
    for p in range(xb.shape[0]):
        xp, yp, mc = xb[p, 0], xb[p, 1], mcs[p]
        ux, uy, ok = _read(S.kind, W, S, G, xp, yp, mc, hx, hy, U, 0)
        vx, vy, _ = _read(S.kind, W, S, G, xp, yp, mc, hx, hy, V1, 0)
        if not ok:
            stranded += 1
        side = B.wall[p]
        if side >= 0:
            if S.bc[side] == 0:
                ux = uy = vx = vy = 0.0
            elif side < 2:
                ux = vx = 0.0
            else:
                uy = vy = 0.0
        B.v[p, 0], B.v[p, 1] = vx, vy
        xb[p, 0] = xp + ux
        xb[p, 1] = yp + uy
    B.drop[4] += stranded
    if stranded > B.drop[5]:
        B.drop[5] = stranded


@njit(cache=True)
def to_band(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, abT, c0, rscale, equilibrate):
    """The Newton matrix straight into band storage (kl = ku = bw), no CSR matrix in between.

    abT, C order, holds column j of A in row j: A[i, j] at abT[j, c0 + i - j] for |i - j| <= bw. c0 = bw: the
    compact layout of band_lu (2 bw + 1 entries per column); c0 = 2 bw: the C-order transpose of LAPACK gbtrf's
    (3 bw + 1, ndof) Fortran array, whose first bw entries per column (gbtrf's fill) are left to gbtrf, which zeroes
    them. Row i of A: the tangent data[rowptr[i]:rowptr[i + 1]] (columns cols) + madd[i] (= m_i /
    (beta dt^2)) on the diagonal; a sliding friction row i (slide_n[i] = n >= 0, its node's held normal dof) minus
    slide_c[i] (= mu s n_in) times row n (the two dof rows of a node share their CSR columns); a held row i the
    identity.
    equilibrate: each row is scaled by a power of two, rscale[i] = 2^-e with |max_j A_ij| in [2^(e-1), 2^e), so all
    rows have their largest entry in [1/2, 1) (exact in floating point: the scaled system has the same solution, and
    partial pivoting then picks pivots by relative, not absolute, size: far fewer row swaps and less fill; the rhs
    is scaled alike by the caller). Otherwise rscale = 1."""
    n = held.shape[0]
    _band_rows(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, abT, c0, rscale, equilibrate, n, False)


@njit(cache=True)
def _band_rows(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, ab, c0, rscale, equilibrate, cut, rev):
    """Rows of the Newton matrix (to_band) into ab. rev = False: rows and columns < cut (ab holds A[:cut, :cut]:
    to_band with cut = n, the top half of band_lu's twisted factorization with cut = m + bw); rev = True: rows
    >= cut - bw (the separator S and B), the entries with i >= cut or j >= cut, reversed (A[i, j] at ab[n - 1 - j,
    c0 + j - i]: the bottom half, whose S x S block stays zero). Each writes rscale only for its own rows (rev:
    i >= cut)."""
    n = held.shape[0]
    i_lo, i_hi = (cut - bw, n) if rev else (0, cut)
    rows = i_hi - i_lo
    ab[:rows, c0 - bw:c0 + bw + 1] = 0.0
    mx = 0
    for i in range(i_lo, i_hi):
        mx = max(mx, rowptr[i + 1] - rowptr[i])
    buf = np.empty(mx)
    for i in range(i_lo, i_hi):
        own = not rev or i >= cut
        if held[i]:
            if own:
                rscale[i] = 1.0
                if rev:
                    ab[n - 1 - i, c0] = 1.0
                else:
                    ab[i, c0] = 1.0
            continue
        nn = slide_n[i]
        r0 = rowptr[i]
        big = 0.0
        for k in range(r0, rowptr[i + 1]):
            v = data[k]
            if k == diag[i]:
                v += madd[i]
            if nn >= 0:
                kn = k - r0 + rowptr[nn]
                w = data[kn]
                if kn == diag[nn]:
                    w += madd[nn]
                v -= slide_c[i] * w
            buf[k - r0] = v
            if abs(v) > big:
                big = abs(v)
        sc = 1.0
        if equilibrate and big > 0.0 and big < np.inf:
            sc = math.ldexp(1.0, -math.frexp(big)[1])
        if own:
            rscale[i] = sc
        for k in range(r0, rowptr[i + 1]):
            j = cols[k]
            if rev:
                if own or j >= cut:
                    ab[n - 1 - j, c0 + j - i] = buf[k - r0] * sc
            elif j < cut:
                ab[j, c0 + i - j] = buf[k - r0] * sc


@njit(cache=True, parallel=True)
def to_band_factor_twisted(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, top, bot, m, rscale, tau):
    """The Newton matrix into band_lu's two twisted halves and their factorization, one half per thread (the same
    bits on one thread): returns band_lu.factor's code for the whole matrix (-1 factored; k >= 0 a column that
    needs a row swap, -2 - k a zero pivot at dof k)."""
    n = held.shape[0]
    nt = m + bw
    code = np.full(2, -1)
    for t in prange(2):
        if t == 0:
            _band_rows(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, top, bw, rscale, True, nt, False)
            code[0] = BL.factor(top, nt, bw, bw, bw, tau, 0, m)
        else:
            _band_rows(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, bot, bw, rscale, True, nt, True)
            code[1] = BL.factor(bot, n - m, bw, bw, bw, tau, 0, n - m - bw)
    if code[0] != -1:
        return code[0]
    k = code[1]
    if k >= 0:
        return n - 1 - k
    if k <= -2:
        return -2 - (n - 1 - (-2 - k))
    BL.join_separator(top, bot, n, m, bw, bw)
    return BL.factor(top, nt, bw, bw, bw, tau, m, nt)
