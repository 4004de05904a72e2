"""Analytic reference solutions (computed, never typed in)."""
from __future__ import annotations

import math

from scipy.special import gamma

# t_c = 2 delta_max / v * int_0^1 du / sqrt(1 - u^(5/2)) = 2 sqrt(pi) Gamma(7/5) / Gamma(9/10) * delta_max / v
HERTZ_TC_FACTOR = 2.0 * math.sqrt(math.pi) * gamma(1.4) / gamma(0.9)


def hertz_impact(estar: float, rstar: float, mstar: float, v: float) -> dict:
    """Elastic Hertz impact (Johnson 1985, sec. 11.1): max overlap, peak force, contact duration."""
    k = 4.0 / 3.0 * estar * math.sqrt(rstar)
    dmax = (15.0 * mstar * v * v / (16.0 * estar * math.sqrt(rstar))) ** 0.4
    return {"max_overlap": dmax, "peak_force": k * dmax ** 1.5, "contact_time": HERTZ_TC_FACTOR * dmax / v}


def sliding_impact(mu: float, e: float, m: float, vn: float, radius: float) -> dict:
    """Oblique impact in gross sliding (Maw et al. 1976 limit): J_t = mu (1+e) m v_n, spin = J_t R / (2/5 m R^2)."""
    jt = mu * (1.0 + e) * m * vn
    return {"tangential_impulse": jt, "exit_spin": jt * radius / (0.4 * m * radius * radius)}


def slide_stop_distance(v0: float, mu: float, g: float) -> float:
    return v0 * v0 / (2.0 * mu * g)


def oedometric_modulus(young: float, poisson: float) -> float:
    """Constrained (oedometric) modulus M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) [Pa]."""
    return young * (1 - poisson) / ((1 + poisson) * (1 - 2 * poisson))


def geostatic_stress(density: float, g: float, surface: float, y):
    """Vertical stress of a column at rest under its own weight, sigma_yy(y) = -rho g (H - y) [Pa] (H = surface)."""
    return -density * g * (surface - y)


def self_weight_settlement(density: float, g: float, height: float, modulus: float) -> float:
    """Top settlement of an elastic column of height H on a fixed base, 1D small strain: rho g H^2 / (2 M) [m]."""
    return density * g * height ** 2 / (2 * modulus)


def bar_period(length: float, young: float, density: float) -> float:
    """First-mode period of a fixed-free elastic bar (1D, nu = 0): T = 4 L / c, c = sqrt(E / rho) [s]."""
    return 4 * length / math.sqrt(young / density)


def self_weight_settlement_log(density: float, g: float, height: float, modulus: float) -> float:
    """The same column with a rate (hypoelastic) law, sigma_yy = M ln(lambda) (lambda = dy/dy0, 1D, the MPM's
    stress update with the velocity gradient): lambda(y0) = exp(-rho g (H - y0) / M) since the weight above y0 is
    rho g (H - y0) whatever the deformation, so u_top = H - M / (rho g) (1 - exp(-rho g H / M)) [m]. Equals
    rho g H^2 / (2 M) to first order in the strain rho g H / M."""
    a = density * g * height / modulus
    return height - height / a * (-math.expm1(-a))
