"""Verlet neighbour list with a cell list and a skin (rebuilt only when a sphere moved more than skin/2).

Pairs (i < j) are stored CSR-style by i with j sorted inside each segment, so the tangential history of a pair
can be found again after a rebuild by binary search. `jstart/jlist` is the transposed incidence (pairs where a
sphere is j), so forces are gathered per sphere in a fixed order: results do not depend on the thread count.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _cell_coords(x, lo, inv_h, nc):
    c0 = int((x[0] - lo[0]) * inv_h)
    c1 = int((x[1] - lo[1]) * inv_h)
    c2 = int((x[2] - lo[2]) * inv_h)
    c0 = min(max(c0, 0), nc[0] - 1)
    c1 = min(max(c1, 0), nc[1] - 1)
    c2 = min(max(c2, 0), nc[2] - 1)
    return c0, c1, c2


@njit(cache=True)
def _bin(x, lo, inv_h, nc):
    n = x.shape[0]
    ncell = nc[0] * nc[1] * nc[2]
    cell_start = np.zeros(ncell + 1, np.int64)
    cell_of = np.empty(n, np.int64)
    for i in range(n):
        c0, c1, c2 = _cell_coords(x[i], lo, inv_h, nc)
        c = (c0 * nc[1] + c1) * nc[2] + c2
        cell_of[i] = c
        cell_start[c + 1] += 1
    for c in range(ncell):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):
        c = cell_of[i]
        items[fill[c]] = i
        fill[c] += 1
    return cell_start, items


@njit(cache=True, parallel=True)
def _count_or_fill(x, r, body, skin, lo, inv_h, nc, cell_start, items, offsets, pj, fill):
    n = x.shape[0]
    for i in prange(n):
        c0, c1, c2 = _cell_coords(x[i], lo, inv_h, nc)
        k = 0
        base = offsets[i] if fill else 0
        for a in range(max(c0 - 1, 0), min(c0 + 2, nc[0])):
            for b in range(max(c1 - 1, 0), min(c1 + 2, nc[1])):
                for c in range(max(c2 - 1, 0), min(c2 + 2, nc[2])):
                    cell = (a * nc[1] + b) * nc[2] + c
                    for s in range(cell_start[cell], cell_start[cell + 1]):
                        j = items[s]
                        if j <= i:
                            continue
                        if body[i] >= 0 and body[i] == body[j]:
                            continue            # members of one rigid cluster never touch
                        dx = x[j, 0] - x[i, 0]
                        dy = x[j, 1] - x[i, 1]
                        dz = x[j, 2] - x[i, 2]
                        cut = r[i] + r[j] + skin
                        if dx * dx + dy * dy + dz * dz < cut * cut:
                            if fill:
                                pj[base + k] = j
                            k += 1
        if fill:
            # insertion sort of the segment by j (short segments)
            for u in range(base + 1, base + k):
                v = pj[u]
                w = u - 1
                while w >= base and pj[w] > v:
                    pj[w + 1] = pj[w]
                    w -= 1
                pj[w + 1] = v
        else:
            offsets[i + 1] = k


@njit(cache=True)
def _transpose(n, offsets, pj):
    npair = pj.shape[0]
    pi = np.empty(npair, np.int32)
    for i in range(n):
        for k in range(offsets[i], offsets[i + 1]):
            pi[k] = i
    jstart = np.zeros(n + 1, np.int32)
    for k in range(npair):
        jstart[pj[k] + 1] += 1
    for i in range(n):
        jstart[i + 1] += jstart[i]
    fill = jstart[:-1].copy()
    jlist = np.empty(npair, np.int32)
    for k in range(npair):
        j = pj[k]
        jlist[fill[j]] = k
        fill[j] += 1
    return pi, jstart, jlist


def build_pairs(x: np.ndarray, r: np.ndarray, body: np.ndarray, skin: float):
    """Return offsets (n+1), pi, pj (int32), jstart (n+1), jlist for all pairs closer than r_i + r_j + skin."""
    n = x.shape[0]
    lo = x.min(axis=0) - 1e-12
    hi = x.max(axis=0) + 1e-12
    h = 2.0 * float(r.max()) + skin
    ext = np.maximum(hi - lo, h)
    # keep the number of cells O(n): coarsen the cells for very sparse clouds
    while np.prod(np.ceil(ext / h)) > 8 * n + 27:
        h *= 1.5
    nc = np.maximum(np.ceil(ext / h).astype(np.int64), 1)
    inv_h = 1.0 / h
    cell_start, items = _bin(x, lo, inv_h, nc)
    offsets = np.zeros(n + 1, np.int64)
    dummy = np.empty(0, np.int32)
    _count_or_fill(x, r, body, skin, lo, inv_h, nc, cell_start, items, offsets, dummy, False)
    np.cumsum(offsets, out=offsets)
    pj = np.empty(int(offsets[-1]), np.int32)
    _count_or_fill(x, r, body, skin, lo, inv_h, nc, cell_start, items, offsets, pj, True)
    pi, jstart, jlist = _transpose(n, offsets, pj)
    return offsets.astype(np.int32), pi, pj, jstart, jlist


@njit(cache=True, parallel=True)
def carry_pair_state(n, old_off, old_pj, new_off, new_pj, old_state, new_state):
    """Copy per-pair state rows (history, stored energy, last force) of pairs present in both lists."""
    for i in prange(n):
        a0, a1 = old_off[i], old_off[i + 1]
        for k in range(new_off[i], new_off[i + 1]):
            j = new_pj[k]
            lo, hi = a0, a1
            while lo < hi:                   # binary search j in the old, sorted segment
                mid = (lo + hi) // 2
                if old_pj[mid] < j:
                    lo = mid + 1
                else:
                    hi = mid
            if lo < a1 and old_pj[lo] == j:
                for c in range(old_state.shape[1]):
                    new_state[k, c] = old_state[lo, c]
            else:
                for c in range(new_state.shape[1]):
                    new_state[k, c] = 0.0


def default_skin(rmin: float) -> float:
    return 0.3 * rmin if math.isfinite(rmin) else 1e-4
