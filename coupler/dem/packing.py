"""`[[dem.packings]]`: random sequential addition (RSA) of non-overlapping spheres in a box.

Candidates are drawn uniformly in the box shrunk by r_max, in batches of BATCH from the packing's seeded generator;
the spheres are placed largest first, each candidate accepted when its distance to every placed sphere is at least
the sum of the radii. The overlap test looks only at the 3^dim cells around the candidate in a cell grid of side
>= 2 r_max (the farthest a touching neighbour can be), so a packing of N spheres costs O(N) tests, not O(N^2).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from coupler.errors import SceneError

BATCH = 256             # candidates drawn per generator call (fixes the stream: the packing of a seed)
CELLS_PER_SPHERE = 8    # the grid is coarsened to at most this many cells per sphere (a sparse box stays small)


@njit(cache=True)
def _place(cand, r_all, x, n, count, head, nxt, lo, cell, dims):
    """Place the candidates of one batch in turn; returns the new number of placed spheres. head / nxt: a linked
    list of the spheres per cell (-1 ends it); dims = cells per axis (1 on an unused axis)."""
    for c in range(cand.shape[0]):
        if n >= count:
            break
        r = r_all[n]
        ci = np.empty(3, np.int64)
        for a in range(3):
            ci[a] = min(max(int((cand[c, a] - lo[a]) / cell), 0), dims[a] - 1)
        ok = True
        for i in range(max(ci[0] - 1, 0), min(ci[0] + 2, dims[0])):
            for j in range(max(ci[1] - 1, 0), min(ci[1] + 2, dims[1])):
                for k in range(max(ci[2] - 1, 0), min(ci[2] + 2, dims[2])):
                    p = head[(i * dims[1] + j) * dims[2] + k]
                    while p >= 0:
                        dx = x[p, 0] - cand[c, 0]
                        dy = x[p, 1] - cand[c, 1]
                        dz = x[p, 2] - cand[c, 2]
                        if math.sqrt(dx * dx + dy * dy + dz * dz) < r + r_all[p]:
                            ok = False
                            break
                        p = nxt[p]
                    if not ok:
                        break
                if not ok:
                    break
            if not ok:
                break
        if ok:
            x[n, 0], x[n, 1], x[n, 2] = cand[c, 0], cand[c, 1], cand[c, 2]
            key = (ci[0] * dims[1] + ci[1]) * dims[2] + ci[2]
            nxt[n] = head[key]
            head[key] = n
            n += 1
    return n


def random_packing(path: str, lo, hi, count: int, rmin: float, rmax: float, seed: int, dim: int):
    """`count` spheres with radii uniform in [rmin, rmax], sorted largest first, fully inside [lo, hi];
    returns (radii, centres (count, 3)). SceneError naming `path` when the box cannot hold them."""
    rng = np.random.default_rng(seed)
    r_all = rng.uniform(rmin, rmax, count) if rmax > rmin else np.full(count, rmin)
    r_all = np.sort(r_all)[::-1].copy()
    inner_lo, inner_hi = np.array(lo, float) + rmax, np.array(hi, float) - rmax
    if dim == 2:
        inner_lo[2] = inner_hi[2] = lo[2]
    if np.any(inner_hi[:dim] < inner_lo[:dim]):
        raise SceneError(path, "the box is smaller than one sphere")
    span = np.maximum(inner_hi - inner_lo, 0.0)
    cell = max(2.0 * rmax, (np.prod(span[:dim]) / (CELLS_PER_SPHERE * count)) ** (1.0 / dim))
    dims = np.array([max(1, int(s / cell) + 1) if a < dim else 1 for a, s in enumerate(span)], dtype=np.int64)
    head = np.full(int(np.prod(dims)), -1, dtype=np.int64)
    nxt = np.full(count, -1, dtype=np.int64)
    x = np.zeros((count, 3))
    n, tries, max_tries = 0, 0, 200 * count + 10000
    while n < count and tries < max_tries:
        cand = rng.uniform(inner_lo, inner_hi, (BATCH, 3))
        if dim == 2:
            cand[:, 2] = lo[2]
        tries += BATCH
        n = _place(cand, r_all, x, n, count, head, nxt, inner_lo, cell, dims)
    if n < count:
        raise SceneError(path, f"could place only {n} of {count} non-overlapping spheres in the box "
                               f"(lower count or enlarge box)")
    return r_all, x
