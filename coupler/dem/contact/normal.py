"""Normal sub-models. Each returns (S, S_t, F_el, E_el) for the overlap d:
S the stiffness of the normal dashpot (gamma_n = 2 beta sqrt(S m*)), S_t the tangential stiffness,
F_el the elastic normal force and E_el its stored energy.

    hertz:  S = S_n = 2 E* sqrt(R* d), S_t = 8 G* sqrt(R* d), F_el = 2/3 S_n d = 4/3 E* sqrt(R*) d^(3/2),
            E_el = 4/15 S_n d^2 = 8/15 E* sqrt(R*) d^(5/2)     (LIGGGHTS `model hertz`, YADE Mindlin)
    hooke:  S = k_n (scene `stiffness`, N/m), S_t = ratio k_n (scene `tangential_ratio`, default 2/7 as
            LAMMPS `gran/hooke/history` with kt = NULL), F_el = k_n d, E_el = 1/2 k_n d^2

1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2, 1/G* = 2(2-nu1)(1+nu1)/E1 + 2(2-nu2)(1+nu2)/E2, R* = R1 R2/(R1+R2) (wall: R).
"""
from __future__ import annotations

import math

from numba import njit

HERTZ = 0
HOOKE = 1


def effective_young(a, b) -> float:
    return 1.0 / ((1.0 - a.poisson ** 2) / a.young + (1.0 - b.poisson ** 2) / b.young)


def effective_shear(a, b) -> float:
    return 1.0 / (2.0 * (2.0 - a.poisson) * (1.0 + a.poisson) / a.young
                  + 2.0 * (2.0 - b.poisson) * (1.0 + b.poisson) / b.young)


@njit(cache=True, inline="always")
def hertz(delta, rstar, estar, gstar):
    sqrt_rd = math.sqrt(rstar * delta)
    sn = 2.0 * estar * sqrt_rd
    st = 8.0 * gstar * sqrt_rd
    return sn, st, (2.0 / 3.0) * sn * delta, (4.0 / 15.0) * sn * delta * delta


@njit(cache=True, inline="always")
def hooke(delta, kn, ratio):
    return kn, ratio * kn, kn * delta, 0.5 * kn * delta * delta


@njit(cache=True, inline="always")
def normal_force(model, delta, rstar, estar, gstar, kn, ratio):
    if model == HOOKE:
        return hooke(delta, kn, ratio)
    return hertz(delta, rstar, estar, gstar)
