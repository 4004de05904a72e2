"""Shape functions on a uniform grid (1D factors; 2D weight = wx(x) * wy(y)). Registry by name and id.

Each kind gives, for a point coordinate xi in cell units (node i at xi = i), the first node index i0 of its
support and the weights / derivatives d/dxi of the consecutive nodes i0, i0+1, ... of its support. The support
width (nodes per direction) is a registry column, `WIDTH[id]`: the kernels loop over exactly that many nodes
(coupler/mpm/kernels.py compiles one copy of each transfer per registered shape with its width as a constant).
`weights3` returns MAX_WIDTH = 3 entries; those beyond the width of the kind are 0 and never read by the kernels.
`width(id)` / `check_shape(id)` raise ValueError for an id that is not registered.

Adding a shape: a branch in `first_node` and `weights3`, a row in SHAPES, and its compiled copies in kernels.py
(`_scatter_<name>`, `_g2p_<name>`, `_remap_<name>` and the branches that pick them by id).
  linear     : hat functions (Sulsky et al. 1994)
  gimp       : uGIMP with particle half-width lp = h/(2 ppc_1d) (Bardenhagen & Kober 2004)
  bspline2   : quadratic B-spline (Steffen et al. 2008), boundary-modified at the grid box [lo, hi]: the function
               of the ghost node outside a wall is handed to the wall node and its neighbour so that partition of
               unity and linear reproduction still hold (ghost value = linear extrapolation 2 v_0 - v_1). In the
               half cell next to the wall this leaves N_wall = 1 - s, N_1 = s (s = distance to the wall in cells),
               C1 with the uniform spline at s = 1/2. So the wall nodes alone give the velocity on the wall (the
               uniform spline there mixes in the first interior node: 1/8 v_-1 + 3/4 v_0 + 1/8 v_1), and a point
               at distance s moves towards the wall by at most s |v_1| dt / h per step: it cannot cross a wall
               whose nodes have no velocity into it while |v_1| dt < h (CFL).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

LINEAR, GIMP, BSPLINE2 = 0, 1, 2
# registry: name -> (id, support width in nodes per direction)
SHAPES = {"linear": (LINEAR, 2), "gimp": (GIMP, 3), "bspline2": (BSPLINE2, 3)}
REGISTRY = {name: sid for name, (sid, _) in SHAPES.items()}
SUPPORT = {sid: w for sid, w in SHAPES.values()}
WIDTH = tuple(SUPPORT[i] for i in range(len(SUPPORT)))     # by id (a constant tuple inside compiled code)
MAX_WIDTH = 3


def check_shape(kind) -> int:
    """The shape id as an int; ValueError naming the registered ids if it is not one of them."""
    k = int(kind)
    if k != kind or k not in SUPPORT:
        raise ValueError(f"unknown shape function id {kind!r} (registered: "
                         + ", ".join(f"{sid} = {name}" for name, (sid, _) in SHAPES.items()) + ")")
    return k


def width(kind) -> int:
    """Support width (nodes per direction) of a registered shape id."""
    return SUPPORT[check_shape(kind)]


@njit(cache=True, inline="always")
def first_node(kind, xi):
    """First node of the support of a point at xi (cell units); the same index weights3 returns."""
    if kind == 0:
        return int(math.floor(xi))
    if kind == 2:
        return int(math.floor(xi - 0.5))
    return int(math.floor(xi + 0.5)) - 1


@njit(cache=True, inline="always")
def weights3(kind, xi, lp, lo, hi):
    """Returns (i0, (w0, w1, w2), (dw0, dw1, dw2)) for the nodes i0..i0+2; lo, hi: the walls of the grid box
    (node coordinates, cell units) for the boundary-modified B-spline. Tuples, so that the kernels keep them in
    registers and loop over a fixed 3 nodes."""
    if kind == 2:
        i0 = int(math.floor(xi - 0.5))
        if xi < lo + 0.5:           # half cell next to the low wall: nodes (ghost, lo, lo + 1)
            s = xi - lo
            return i0, (0.0, 1.0 - s, s), (0.0, -1.0, 1.0)
        if xi > hi - 0.5:           # next to the high wall: nodes (hi - 1, hi, ghost)
            s = hi - xi
            return i0, (s, 1.0 - s, 0.0), (-1.0, 1.0, 0.0)
        f = xi - i0                 # in [0.5, 1.5): distances to nodes i0, i0+1, i0+2 are f, f-1, f-2
        d0 = 1.5 - f
        d1 = f - 1.0
        d2 = f - 0.5
        return i0, (0.5 * d0 * d0, 0.75 - d1 * d1, 0.5 * d2 * d2), (-d0, -2.0 * d1, d2)
    if kind == 0:
        i0 = int(math.floor(xi))
        f = xi - i0
        return i0, (1.0 - f, f, 0.0), (-1.0, 1.0, 0.0)
    # uGIMP, lp < 0.5 (cell units): nodes i0..i0+2 with i0 = round(xi) - 1
    i0 = int(math.floor(xi + 0.5)) - 1
    w0, d0 = _gimp(xi - i0, lp)
    w1, d1 = _gimp(xi - (i0 + 1), lp)
    w2, d2 = _gimp(xi - (i0 + 2), lp)
    return i0, (w0, w1, w2), (d0, d1, d2)


@njit(cache=True, inline="always")
def _gimp(r, lp):
    a = abs(r)
    s = 1.0 if r >= 0.0 else -1.0
    if a < lp:
        return 1.0 - (r * r + lp * lp) / (2.0 * lp), -r / lp
    if a < 1.0 - lp:
        return 1.0 - a, -s
    if a < 1.0 + lp:
        t = 1.0 + lp - a
        return t * t / (4.0 * lp), -s * t / (2.0 * lp)
    return 0.0, 0.0


def evaluate(kind: int, xi: np.ndarray, lp: float = 0.25, lo: float = -1e300, hi: float = 1e300):
    """Python helper for tests: returns (i0, w[n,3], dw[n,3]) (columns beyond the support width are 0)."""
    check_shape(kind)
    n = len(xi)
    w = np.zeros((n, 3))
    dw = np.zeros((n, 3))
    i0 = np.zeros(n, dtype=np.int64)
    for p in range(n):
        i0[p], w[p], dw[p] = _eval1(kind, float(xi[p]), lp, lo, hi)
    return i0, w, dw


@njit(cache=True)
def _eval1(kind, xi, lp, lo, hi):
    i0, w, dw = weights3(kind, xi, lp, lo, hi)
    return i0, np.array(w), np.array(dw)
