"""Hertz-Mindlin spring-dashpot contact with Coulomb friction and tangential history.

Definitions (the same for sphere-sphere and sphere-wall; LIGGGHTS 3.8 `normal_model_hertz.h`,
`tangential_model_history.h`, Di Renzo & Di Maio 2004, Tsuji et al. 1992):

    1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2            1/G* = 2(2-nu1)(1+nu1)/E1 + 2(2-nu2)(1+nu2)/E2
    R*   = R1 R2/(R1+R2)   (wall: R* = R)         m* = m1 m2/(m1+m2)   (wall: m* = m; clusters: see below)
    S_n  = 2 E* sqrt(R* d)                        S_t = 8 G* sqrt(R* d)          d = overlap
    F_n  = max(0, 4/3 E* sqrt(R*) d^(3/2) + gamma_n v_n)     gamma_n = 2 beta sqrt(S_n m*)
    xi  <- project(xi) + v_t dt                   F_t = -S_t xi - gamma_t v_t,   gamma_t = 2 beta sqrt(S_t m*)
    if |S_t xi| > mu F_n:  xi <- xi mu F_n/|S_t xi|,  F_t = -S_t xi   (no dashpot while sliding)

The normal force is never attractive (F_n >= 0). The tangential dashpot acts only while sticking and the Coulomb cap
uses the total F_n, as both LIGGGHTS and YADE do (shared/notes/dem_codes.md P9, P17).

`beta` (the damping ratio of this module) is one number per material pair. How the coefficient of restitution e
maps to it is the contact law's `damping` mode:
  * "restitution": beta such that a binary impact *with* the F_n >= 0 clamp rebounds with exactly e
    (inverse of the clamped, velocity-independent Hertz ODE below; the default).
  * "liggghts": beta = sqrt(5/6) |ln e| / sqrt(ln^2 e + pi^2)   (LIGGGHTS; with the clamp e=0.8 gives 0.808).
  * "yade": beta_n from Thornton et al. (2013) eq. (B6), as YADE's `Ip2_FrictMat_FrictMat_MindlinPhys(en=...)`.
YADE writes c_n = 2 beta_n sqrt(mbar k_n) with k_n = 3/2 k_no sqrt(d) = S_n: the same form as above.

Cluster contacts: m* uses the damping mass of each member sphere: the cluster's body mass ("body", LIGGGHTS
multisphere) or the member sphere's own mass ("sphere", YADE clumps).
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from coupler.scene import ContactLaw, Material


def effective_young(a: Material, b: Material) -> float:
    return 1.0 / ((1.0 - a.poisson ** 2) / a.young + (1.0 - b.poisson ** 2) / b.young)


def effective_shear(a: Material, b: Material) -> float:
    return 1.0 / (2.0 * (2.0 - a.poisson) * (1.0 + a.poisson) / a.young
                  + 2.0 * (2.0 - b.poisson) * (1.0 + b.poisson) / b.young)


def beta_liggghts(e: float) -> float:
    """LIGGGHTS: gamma_n = 2 sqrt(5/6) |ln e|/sqrt(ln^2 e + pi^2) sqrt(S_n m*)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return math.sqrt(5.0 / 6.0) * abs(le) / math.sqrt(le * le + math.pi ** 2)


_THORNTON_B6 = (-6.918798, -16.41105, 146.8049, -796.4559, 2928.711, -7206.864, 11494.29, -11342.18,
                6276.757, -1489.915)


def beta_yade(e: float) -> float:
    """YADE `en=`: Thornton, Cummins & Cleary (2013), Powder Technol. 233, eq. (B6)."""
    if e >= 1.0:
        return 0.0
    acc = _THORNTON_B6[-1]
    for c in reversed(_THORNTON_B6[:-1]):
        acc = c + e * acc
    alpha = e * acc
    return math.sqrt(1.0 / (1.0 - (1.0 + e) ** 2 * math.exp(alpha)) - 1.0)


def restitution_clamped(beta: float) -> float:
    """Restitution of the Hertz spring-dashpot above with F_n >= 0, for damping ratio beta.

    Scaled ODE (m* = 1, 4/3 E* sqrt(R*) = 1, v0 = 1): u'' = -max(0, u^1.5 + 2 beta sqrt(3/2) u^0.25 u').
    The law is velocity independent, so e depends on beta only. Contact ends when the force reaches zero.
    """
    if beta == 0.0:
        return 1.0
    c = 2.0 * beta * math.sqrt(1.5)

    def rhs(_t, y):
        u, w = y
        u = max(u, 0.0)
        f = u ** 1.5 + c * u ** 0.25 * w
        return [w, -max(f, 0.0)]

    def force_zero(_t, y):
        u, w = y
        return max(u, 0.0) ** 1.5 + c * max(u, 0.0) ** 0.25 * w

    force_zero.terminal = True
    force_zero.direction = -1

    def overlap_zero(_t, y):
        return y[0]

    overlap_zero.terminal = True
    overlap_zero.direction = -1
    # start slightly inside so the force event is well defined; the tiny initial work is negligible (u0 = 1e-12)
    u0 = 1e-12
    sol = solve_ivp(rhs, (0.0, 50.0), [u0, 1.0], method="DOP853", rtol=1e-12, atol=1e-15,
                    events=(force_zero, overlap_zero))
    # first terminal event after the compression phase (w < 0)
    w_end = sol.y[1, -1]
    return -w_end


@lru_cache(maxsize=256)
def beta_restitution(e: float) -> float:
    """Damping ratio that delivers restitution e with the F_n >= 0 clamp (inverse of restitution_clamped)."""
    if e >= 1.0:
        return 0.0
    lo, hi = 0.0, beta_liggghts(e)
    while restitution_clamped(hi) > e:
        hi *= 2.0
        if hi > 1e4:
            raise ValueError(f"restitution {e} cannot be reached")
    return brentq(lambda b: restitution_clamped(b) - e, lo, hi, xtol=1e-14, rtol=1e-13)


def damping_ratio(law: ContactLaw) -> float:
    e = law.restitution
    if law.damping == "restitution":
        return beta_restitution(e)
    if law.damping == "liggghts":
        return beta_liggghts(e)
    if law.damping == "yade":
        return beta_yade(e)
    raise ValueError(f"unknown damping mode {law.damping!r}")


def law_table(materials: list[Material], laws: dict) -> np.ndarray:
    """(nmat, nmat, 5) table: E*, G*, beta, mu, history flag (1/0). laws: dict[(a, b)] -> ContactLaw."""
    from coupler.scene import pair_key
    n = len(materials)
    tab = np.zeros((n, n, 5))
    for i, a in enumerate(materials):
        for j, b in enumerate(materials):
            key = pair_key(a.name, b.name)
            if key not in laws:
                tab[i, j, :] = np.nan  # never touched: finish_dem checks every used pair has a law
                continue
            law = laws[key]
            tab[i, j] = (effective_young(a, b), effective_shear(a, b), damping_ratio(law), law.friction,
                         1.0 if law.tangential_history else 0.0)
    return tab


@njit(cache=True, inline="always")
def hertz_mindlin(delta, nx, ny, nz, vx, vy, vz, rstar, mstar, estar, gstar, beta, mu, hist, dt, x0, x1, x2):
    """Contact force on body i for overlap `delta`, unit normal n (from i towards j) and contact-point velocity
    v = v_i - v_j; (x0, x1, x2) is the tangential history xi (hist == 0: no history).

    Returns (fx, fy, fz, fn, ft, elastic_energy, xi0, xi1, xi2). Force on j is the opposite.
    Scalars only, so it inlines into the loops without array reference counting.
    """
    sqrt_rd = math.sqrt(rstar * delta)
    sn = 2.0 * estar * sqrt_rd
    st = 8.0 * gstar * sqrt_rd
    vn = vx * nx + vy * ny + vz * nz                    # > 0 approaching
    fn = (2.0 / 3.0) * sn * delta + 2.0 * beta * math.sqrt(sn * mstar) * vn
    if fn < 0.0:
        fn = 0.0
    vtx = vx - vn * nx
    vty = vy - vn * ny
    vtz = vz - vn * nz
    if hist != 0.0:
        x0 += vtx * dt
        x1 += vty * dt
        x2 += vtz * dt
        r = x0 * nx + x1 * ny + x2 * nz                 # keep the spring in the tangent plane
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
    if ft_el > fric:
        ratio = fric / ft_el
        ftx *= ratio
        fty *= ratio
        ftz *= ratio
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
        if hist == 0.0:                                 # no history: a capped dashpot
            fmag = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
            if fmag > fric:
                ratio = fric / fmag
                ftx *= ratio
                fty *= ratio
                ftz *= ratio
    e_n = (4.0 / 15.0) * sn * delta * delta   # = 8/15 E* sqrt(R*) d^(5/2)
    fx = -fn * nx + ftx
    fy = -fn * ny + fty
    fz = -fn * nz + ftz
    ft = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
    return fx, fy, fz, fn, ft, e_n + e_t, x0, x1, x2
