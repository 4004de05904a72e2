"""Damping sub-models: how the coefficient of restitution e becomes the damping ratio beta.

The dashpot is the same for every normal model, gamma = 2 beta sqrt(S m*) with S the normal model's stiffness
(S_n for the normal, S_t for the tangential dashpot). Modes (the contact law's `damping` field):

  * "restitution": beta such that a binary impact *with* the F_n >= 0 clamp rebounds with exactly e (inverse of
    the clamped, velocity-independent spring-dashpot ODE of the normal model; the default).
  * "liggghts": LIGGGHTS 3.8. Hertz: beta = sqrt(5/6) |ln e| / sqrt(ln^2 e + pi^2) (with the clamp e = 0.8 gives
    0.808); Hooke: beta = |ln e| / sqrt(ln^2 e + pi^2) (the unclamped linear oscillator, `normal_model_hooke.h`).
  * "yade": beta_n from Thornton et al. (2013) eq. (B6), as YADE's `Ip2_FrictMat_FrictMat_MindlinPhys(en=...)`
    (Hertz only: YADE has no Hooke law with a restitution input).

YADE writes c_n = 2 beta_n sqrt(mbar k_n) with k_n = 3/2 k_no sqrt(d) = S_n: the same form.
"""
from __future__ import annotations

import math
from functools import lru_cache

from scipy.integrate import solve_ivp
from scipy.optimize import brentq


def beta_liggghts(e: float) -> float:
    """LIGGGHTS Hertz: gamma_n = 2 sqrt(5/6) |ln e|/sqrt(ln^2 e + pi^2) sqrt(S_n m*)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return math.sqrt(5.0 / 6.0) * abs(le) / math.sqrt(le * le + math.pi ** 2)


def beta_liggghts_hooke(e: float) -> float:
    """LIGGGHTS Hooke: gamma_n = sqrt(4 m* k_n / (1 + (pi/ln e)^2)) = 2 |ln e|/sqrt(ln^2 e + pi^2) sqrt(k_n m*)."""
    if e >= 1.0:
        return 0.0
    le = math.log(e)
    return abs(le) / math.sqrt(le * le + math.pi ** 2)


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


def restitution_clamped(beta: float, normal: str = "hertz") -> float:
    """Restitution of the spring-dashpot with F_n >= 0, for damping ratio beta.

    Scaled ODEs (m* = 1, v0 = 1; the laws are velocity independent, so e depends on beta only):
      hertz (4/3 E* sqrt(R*) = 1): u'' = -max(0, u^1.5 + 2 beta sqrt(3/2) u^0.25 u')
      hooke (k_n = 1):             u'' = -max(0, u + 2 beta u')
    Contact ends when the force reaches zero.
    """
    if beta == 0.0:
        return 1.0
    if normal == "hertz":
        c = 2.0 * beta * math.sqrt(1.5)
        pk, pd = 1.5, 0.25
    elif normal == "hooke":
        return _restitution_clamped_hooke(beta)
    else:
        raise ValueError(f"unknown normal model {normal!r}")

    def force(u, w):
        u = max(u, 0.0)
        return u ** pk + c * u ** pd * w

    def rhs(_t, y):
        return [y[1], -max(force(y[0], y[1]), 0.0)]

    def force_zero(_t, y):
        return force(y[0], y[1])

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


def _restitution_clamped_hooke(beta: float) -> float:
    """Closed form of the clamped linear impact (u'' + 2 beta u' + u = 0, u(0) = 0, u'(0) = 1) ending where the
    force u + 2 beta u' reaches zero (before u does): the ODE solution of the Hertz branch carries ~1e-9 of step-size
    noise in e, which a root-finding inverse turns into ~1e-8 in beta."""
    if beta < 1.0:            # underdamped: u = exp(-b t) sin(wd t) / wd, end at wd t = atan2(2 b wd, 2 b^2 - 1)
        wd = math.sqrt(1.0 - beta * beta)
        t = math.atan2(2.0 * beta * wd, 2.0 * beta * beta - 1.0) / wd
        w = math.exp(-beta * t) * (math.cos(wd * t) - beta * math.sin(wd * t) / wd)
    elif beta > 1.0:          # overdamped: sinh / cosh, end at tanh(om t) = 2 b om / (2 b^2 - 1)
        om = math.sqrt(beta * beta - 1.0)
        t = math.atanh(2.0 * beta * om / (2.0 * beta * beta - 1.0)) / om
        w = math.exp(-beta * t) * (math.cosh(om * t) - beta * math.sinh(om * t) / om)
    else:                     # critical: u = t exp(-t), force zero at t = 2
        t = 2.0
        w = math.exp(-t) * (1.0 - t)
    return -w


@lru_cache(maxsize=256)
def beta_restitution(e: float, normal: str = "hertz") -> float:
    """Damping ratio that delivers restitution e with the F_n >= 0 clamp (inverse of restitution_clamped)."""
    if e >= 1.0:
        return 0.0
    lo, hi = 0.0, beta_liggghts(e) if normal == "hertz" else beta_liggghts_hooke(e)
    while restitution_clamped(hi, normal) > e:
        hi *= 2.0
        if hi > 1e4:
            raise ValueError(f"restitution {e} cannot be reached")
    return brentq(lambda b: restitution_clamped(b, normal) - e, lo, hi, xtol=1e-14, rtol=1e-13)


def _yade(e: float, normal: str) -> float:
    if normal != "hertz":
        raise ValueError(f"damping 'yade' (Thornton 2013) is defined for normal 'hertz' only, got {normal!r}")
    return beta_yade(e)


def _liggghts(e: float, normal: str) -> float:
    return beta_liggghts(e) if normal == "hertz" else beta_liggghts_hooke(e)


# registry: one row per damping mode, (e, normal model name) -> beta
DAMPING = {
    "restitution": lambda e, normal: beta_restitution(e) if normal == "hertz" else beta_restitution(e, normal),
    "liggghts": _liggghts,
    "yade": _yade,
}
# damping modes each normal model accepts (scene check)
