"""The compiled per-step exchange of the weak scheme (schemes/gauss_seidel_weak.py) and of the mappers: flat-array
@njit kernels that replace a few dozen small numpy calls per coupling step (issue 14, performance: the coupling's
own cost was ~11 % of the MPM + DEM cost of the coupled bench, all of it Python overhead).

Bitwise contract: every kernel gives the values the numpy expressions they replace gave. Elementwise arithmetic is
the same IEEE operations in the same order (numba does not contract a * b + c into an FMA without fastmath); sums
use `pairwise_sum`, numpy's pairwise summation of np.sum / ndarray.sum (numpy/_core/src/umath/loops_utils.h.src:
blocks of 8 partial sums up to 128 elements, halves above, the identity 0.0 as the start), checked against np.sum in
tests/coupling/test_coupling_exchange.py. Kernels write into preallocated arrays: no per-step allocation.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _block(a, lo, n):
    """numpy's pairwise sum of a[lo:lo + n] for n <= 128: 8 partial sums, combined as a tree, then the rest."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    m = n - n % 8
    i = 8
    while i < m:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def _pw(a, lo, n):
    """numpy's pairwise sum of a[lo:lo + n] (1D, any stride): above 128 elements the sum of the two halves (the
    first of n // 2 rounded down to a multiple of 8), each summed the same way. Iterative (numba does not cache
    recursive functions): a stack of (start, length, stage) and a stack of partial sums."""
    if n <= 128:
        return _block(a, lo, n)
    st_lo = np.empty(64, np.int64)
    st_n = np.empty(64, np.int64)
    st_k = np.empty(64, np.int64)
    vals = np.empty(64)
    sp, vp = 1, 0
    st_lo[0], st_n[0], st_k[0] = lo, n, 0
    while sp > 0:
        t = sp - 1
        if st_n[t] <= 128:
            vals[vp] = _block(a, st_lo[t], st_n[t])
            vp += 1
            sp -= 1
            continue
        n2 = st_n[t] // 2
        n2 -= n2 % 8
        if st_k[t] == 0:            # first half
            st_k[t] = 1
            st_lo[sp], st_n[sp], st_k[sp] = st_lo[t], n2, 0
            sp += 1
        elif st_k[t] == 1:          # second half
            st_k[t] = 2
            st_lo[sp], st_n[sp], st_k[sp] = st_lo[t] + n2, st_n[t] - n2, 0
            sp += 1
        else:                       # both done: first + second
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]
            vp -= 1
            sp -= 1
    return vals[0]


@njit(cache=True)
def pairwise_sum(a):
    """np.sum(a) of a 1D array, bit for bit (0.0 + the pairwise sum)."""
    return 0.0 + _pw(a, 0, a.shape[0])


@njit(cache=True)
def map_kinematics(u, cols, w, identity, out):
    """out = M u (mappers/__init__.py), u (n_mpm, k), out (n_wall, k): w0 u[c0] + w1 u[c1] per wall node."""
    for i in range(out.shape[0]):
        for c in range(out.shape[1]):
            if identity:
                out[i, c] = u[i, c]
            else:
                out[i, c] = w[i, 0] * u[cols[i, 0], c] + w[i, 1] * u[cols[i, 1], c]


@njit(cache=True)
def map_forces(f, cflat, wflat, identity, scale, out):
    """out = (M^T f) / scale, f (n_wall, >= k), out (n_mpm, k): the transpose as np.bincount sums it (entries in
    the order cols[:, 0] then cols[:, 1], each added to 0.0); identity: (f + 0.0) / scale."""
    nn = f.shape[0]
    for c in range(out.shape[1]):
        if identity:
            for i in range(out.shape[0]):
                out[i, c] = (f[i, c] + 0.0) / scale
        else:
            for i in range(out.shape[0]):
                out[i, c] = 0.0
            for e in range(cflat.shape[0]):
                out[cflat[e], c] += wflat[e] * f[e % nn, c]
            for i in range(out.shape[0]):
                out[i, c] = out[i, c] / scale


@njit(cache=True)
def wall_kinematics(xb, xb0, vb, idx, cols, w, identity, wall_x0, linear, v_prev, has_prev, u, vin, xw, vw,
                    x_before):
    """Step 1 of the scheme: the MPM interface kinematics at the start of the step mapped to the wall nodes.
    u = xb - xb0 and v = vb at the interface points idx; xw = wall_x0 + M u; vw = M v, or M (2 v - v_prev) with the
    linear predictor once v_prev exists; then v_prev = v and x_before = xb[idx] (for the MPM interface work)."""
    for j in range(idx.shape[0]):
        p = idx[j]
        for c in range(2):
            u[j, c] = xb[p, c] - xb0[p, c]
            v = vb[p, c]
            vin[j, c] = 2.0 * v - v_prev[j, c] if (linear and has_prev) else v
            v_prev[j, c] = v
            x_before[j, c] = xb[p, c]
    map_kinematics(u, cols, w, identity, xw)
    for i in range(xw.shape[0]):
        for c in range(2):
            xw[i, c] = wall_x0[i, c] + xw[i, c]
    map_kinematics(vin, cols, w, identity, vw)


@njit(cache=True)
def set_wall(x, v, mx, mv, node_force, work, k, scratch):
    """DEMSolver.set_mesh_nodes for a 2D wall (x, v (nn, 2); the mesh arrays (nn, 3), z = 0): work[k] +=
    sum(node_force . (x - mx)) (the jump of the nodes), then mx = x, mv = v. False (nothing changed) when x or v
    is not finite: the caller then raises the solver's own error."""
    nn = x.shape[0]
    for i in range(nn):
        for c in range(2):
            if not (math.isfinite(x[i, c]) and math.isfinite(v[i, c])):
                return False
    for i in range(nn):
        for c in range(3):
            xc = x[i, c] if c < 2 else 0.0
            scratch[3 * i + c] = node_force[i, c] * (xc - mx[i, c])
    work[k] = work[k] + pairwise_sum(scratch[:3 * nn])
    for i in range(nn):
        for c in range(3):
            mx[i, c] = x[i, c] if c < 2 else 0.0
            mv[i, c] = v[i, c] if c < 2 else 0.0
    return True


@njit(cache=True)
def point_loads(F, cflat, wflat, identity, thickness, fbuf, fb, idx, row):
    """Steps 2-3: fbuf = M^T F / thickness [N per unit depth] from the time-averaged wall node forces F (nn, >= 2)
    [N], written to the MPM point loads fb[idx]; row[1:3] = the resultant on the wall (fx_dem, fy_dem). False
    (fb untouched) when a load is not finite."""
    map_forces(F, cflat, wflat, identity, thickness, fbuf)
    for j in range(fbuf.shape[0]):
        for c in range(2):
            if not math.isfinite(fbuf[j, c]):
                return False
    for j in range(idx.shape[0]):
        for c in range(2):
            fb[idx[j], c] = fbuf[j, c]
    row[1] = pairwise_sum(F[:, 0])
    row[2] = pairwise_sum(F[:, 1])
    return True


@njit(cache=True)
def interface_row(xb, idx, x_before, fbuf, drop, drop_prev, thickness, work_dem, row, scratch):
    """Step 4's bookkeeping after the MPM step: the fraction `keep` of this step's load that reached the grid
    (1 - dropped / applied impulse of the step, MPMSolver.drop), the MPM interface work keep th sum(f . dx) and
    row[3:7] = fx_mpm, fy_mpm, work_dem, work_mpm (row[6] holds the cumulative work_mpm). Returns whether load was
    dropped in this step."""
    d1, a1 = drop[1], drop[2]
    keep = 1.0
    dropped = d1 > drop_prev[0]
    if dropped:
        keep = 1.0 - (d1 - drop_prev[0]) / (a1 - drop_prev[1])
    drop_prev[0] = d1
    drop_prev[1] = a1
    n = idx.shape[0]
    for j in range(n):
        for c in range(2):
            scratch[2 * j + c] = fbuf[j, c] * (xb[idx[j], c] - x_before[j, c])
    row[6] = row[6] + keep * thickness * pairwise_sum(scratch[:2 * n])
    row[3] = keep * (pairwise_sum(fbuf[:, 0]) * thickness)
    row[4] = keep * (pairwise_sum(fbuf[:, 1]) * thickness)
    row[5] = work_dem
    return dropped
