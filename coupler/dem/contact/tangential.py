"""Tangential sub-models (Coulomb friction mu, stiffness S_t from the normal model, dashpot 2 beta sqrt(S_t m*)).

    history:     xi <- project(xi) + v_t dt,  F_t = -S_t xi - gamma_t v_t
                 if |S_t xi| > mu F_n: xi <- xi mu F_n/|S_t xi|, F_t = -S_t xi   (no dashpot while sliding)
                 (LIGGGHTS `tangential_model_history.h`: total (secant) spring; the Coulomb cap uses the total
                 F_n and the dashpot acts only while sticking, as LIGGGHTS and YADE, shared/notes P9, P17)
    no_history:  F_t = -gamma_t v_t capped at mu F_n (a viscous-Coulomb law, LIGGGHTS `tangential no_history`)
    incremental: F_e <- project(F_e) - S_t v_t dt,  F_t = F_e - gamma_t v_t
                 if |F_e| > mu F_n: F_e <- F_e mu F_n/|F_e|, F_t = F_e        (no dashpot while sliding)
                 (YADE Law2_ScGeom_MindlinPhys_Mindlin: an incremental (tangent) spring, notes P8: it differs from
                 `history` when S_t changes with the overlap during partial slip; the state is the elastic force
                 F_e [N], not a displacement. YADE rotates F_e with the contact; projecting it on the new tangent
                 plane is the same to first order in the normal's turn per step, without YADE's twist term (zero
                 for planar motion). E_t = |F_e|^2 / (2 S_t), the energy of a spring holding F_e at the present S_t.)

Returns (ftx, fty, ftz, E_t, xi0, xi1, xi2) (xi: the spring state, a displacement or, incremental, a force).
"""
from __future__ import annotations

import math

from numba import njit

NO_HISTORY = 0
HISTORY = 1
INCREMENTAL = 2


@njit(cache=True, inline="always")
def tangential_force(hist, st, beta, mstar, fn, mu, nx, ny, nz, vtx, vty, vtz, dt, x0, x1, x2):
    # the elastic force of the spring: from the state (x0, x1, x2) and this step's tangential motion
    if hist == INCREMENTAL:                             # the state is the elastic force
        r = x0 * nx + x1 * ny + x2 * nz                 # the old force on the new tangent plane
        x0 -= r * nx + st * vtx * dt
        x1 -= r * ny + st * vty * dt
        x2 -= r * nz + st * vtz * dt
        ftx, fty, ftz = x0, x1, x2
    else:
        if hist != NO_HISTORY:                          # the state is the spring's total displacement
            x0 += vtx * dt
            x1 += vty * dt
            x2 += vtz * dt
            r = x0 * nx + x1 * ny + x2 * nz             # keep the spring in the tangent plane
            x0 -= r * nx
            x1 -= r * ny
            x2 -= r * nz
        else:
            x0 = 0.0
            x1 = 0.0
            x2 = 0.0
        ftx = -st * x0
        fty = -st * x1
        ftz = -st * x2
    ft_el = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
    fric = mu * fn
    if ft_el > fric:                                    # sliding: the elastic force on the cone, no dashpot
        ratio = fric / ft_el
        ftx *= ratio
        fty *= ratio
        ftz *= ratio
        if hist == INCREMENTAL:
            x0, x1, x2 = ftx, fty, ftz
        else:
            x0 = -ftx / st
            x1 = -fty / st
            x2 = -ftz / st
        e_t = 0.5 * fric * fric / st
    else:
        e_t = 0.5 * ft_el * ft_el / st if st > 0.0 else 0.0
        gt = 2.0 * beta * math.sqrt(st * mstar)
        ftx -= gt * vtx
        fty -= gt * vty
        ftz -= gt * vtz
        if hist == NO_HISTORY:                          # no history: a capped dashpot
            fmag = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
            if fmag > fric:
                ratio = fric / fmag
                ftx *= ratio
                fty *= ratio
                ftz *= ratio
    return ftx, fty, ftz, e_t, x0, x1, x2
