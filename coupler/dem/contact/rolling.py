"""Rolling-resistance sub-models: a torque M on body i (-M on j) from the rolling part of the relative angular
velocity w_r = w_i - w_j (wall: w_i), w_t = w_r - (w_r . n) n (twist about n is not resisted). mu_r is the
dimensionless rolling coefficient, R* the effective radius (wall: R), F_n the normal force after damping and
clamp (>= 0).

    none:   M = 0
    cdt:    M = -mu_r R* F_n w_t/|w_t|  (constant directional torque; LIGGGHTS 3.8 `rolling_friction cdt`,
            which uses the elastic part k_n d of F_n and, for walls, the arm R - d/2 instead of R*: the same
            in steady rolling on a wall up to d/(2R); YADE has no such law)
    epsd2:  elastic-plastic spring, M <- M - k_r w_t dt, |M| <= mu_r R* F_n (no dashpot; LIGGGHTS 3.8
            `rolling_friction epsd2`, k_r = S_t R*^2 with the tangential stiffness S_t of the normal model;
            YADE `Law2_ScGeom_MindlinPhys_Mindlin(includeMoment=True)` with a constant `krot` and
            maxBendPl = eta Rmean). `stiffness`: "tangential" (k_r = S_t R*^2, default) or a constant k_r
            [N m/rad]. Stored energy |M|^2 / (2 k_r). The spring is kept in the tangent plane.

Returns (mx, my, mz, E_r, m0, m1, m2) with (m0, m1, m2) the state carried to the next step (the torque).
"""
from __future__ import annotations

import math

from numba import njit

NONE = 0
CDT = 1
EPSD2 = 2


@njit(cache=True, inline="always")
def rolling_torque(model, mur, kroll, st, rstar, fn, nx, ny, nz, wx, wy, wz, dt, m0, m1, m2):
    if model == NONE:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    wn = wx * nx + wy * ny + wz * nz
    wtx = wx - wn * nx
    wty = wy - wn * ny
    wtz = wz - wn * nz
    mmax = mur * rstar * fn
    if model == CDT:
        wt = math.sqrt(wtx * wtx + wty * wty + wtz * wtz)
        if wt > 0.0:
            c = -mmax / wt
            return c * wtx, c * wty, c * wtz, 0.0, c * wtx, c * wty, c * wtz
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    kr = st * rstar * rstar if kroll < 0.0 else kroll
    r = m0 * nx + m1 * ny + m2 * nz                 # keep the spring in the tangent plane
    m0 = m0 - r * nx - kr * wtx * dt
    m1 = m1 - r * ny - kr * wty * dt
    m2 = m2 - r * nz - kr * wtz * dt
    mag = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    if mag > mmax:
        s = mmax / mag
        m0 *= s
        m1 *= s
        m2 *= s
    e_r = 0.5 * (m0 * m0 + m1 * m1 + m2 * m2) / kr if kr > 0.0 else 0.0
    return m0, m1, m2, e_r, m0, m1, m2
