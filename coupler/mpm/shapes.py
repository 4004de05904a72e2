"""Shape functions on a uniform grid (1D factors; 2D weight = wx(x) * wy(y)). Registry by name.

Each kind gives, for a point coordinate in cell units, the first node index of its support and the weights /
derivatives of the `SUPPORT[kind]` consecutive nodes. Codes are small ints so the numba kernels branch cheaply.
  linear     : hat functions (Sulsky et al. 1994), support 2
  gimp       : uGIMP with particle half-width lp = h/(2 ppc_1d) (Bardenhagen & Kober 2004), support 3
  bspline2   : quadratic B-spline (Steffen et al. 2008), support 3
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

LINEAR, GIMP, BSPLINE2 = 0, 1, 2
REGISTRY = {"linear": LINEAR, "gimp": GIMP, "bspline2": BSPLINE2}
SUPPORT = {LINEAR: 2, GIMP: 3, BSPLINE2: 3}


@njit(cache=True, inline="always")
def weights_1d(kind, xi, lp, w, dw):
    """xi: coordinate in cell units (node i at xi = i). Fills w[0:3], dw[0:3] (d/dxi); returns first node index."""
    if kind == 0:
        i0 = int(math.floor(xi))
        f = xi - i0
        w[0] = 1.0 - f
        w[1] = f
        w[2] = 0.0
        dw[0] = -1.0
        dw[1] = 1.0
        dw[2] = 0.0
        return i0
    if kind == 2:
        i0 = int(math.floor(xi - 0.5))
        f = xi - i0  # in [0.5, 1.5): distances to nodes i0, i0+1, i0+2 are f, f-1, f-2
        d0 = 1.5 - f
        w[0] = 0.5 * d0 * d0
        dw[0] = -d0
        d1 = f - 1.0
        w[1] = 0.75 - d1 * d1
        dw[1] = -2.0 * d1
        d2 = f - 0.5  # = 1.5 - (2 - f)
        w[2] = 0.5 * d2 * d2
        dw[2] = d2
        return i0
    # uGIMP, lp < 0.5 (cell units): nodes i0..i0+2 with i0 = round(xi) - 1
    i0 = int(math.floor(xi + 0.5)) - 1
    for k in range(3):
        r = xi - (i0 + k)
        a = abs(r)
        s = 1.0 if r >= 0.0 else -1.0
        if a < lp:
            w[k] = 1.0 - (r * r + lp * lp) / (2.0 * lp)
            dw[k] = -r / lp
        elif a < 1.0 - lp:
            w[k] = 1.0 - a
            dw[k] = -s
        elif a < 1.0 + lp:
            t = 1.0 + lp - a
            w[k] = t * t / (4.0 * lp)
            dw[k] = -s * t / (2.0 * lp)
        else:
            w[k] = 0.0
            dw[k] = 0.0
    return i0


def evaluate(kind: int, xi: np.ndarray, lp: float = 0.25):
    """Python helper for tests: returns (i0, w[n,3], dw[n,3])."""
    n = len(xi)
    w = np.zeros((n, 3))
    dw = np.zeros((n, 3))
    i0 = np.zeros(n, dtype=np.int64)
    for p in range(n):
        i0[p] = _eval1(kind, float(xi[p]), lp, w[p], dw[p])
    return i0, w, dw


@njit(cache=True)
def _eval1(kind, xi, lp, w, dw):
    return weights_1d(kind, xi, lp, w, dw)
