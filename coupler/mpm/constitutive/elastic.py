"""Linear isotropic (hypo-)elastic law with the Jaumann rate (coupler/mpm/materials.py)."""
from __future__ import annotations

from dataclasses import dataclass

from numba import njit

from coupler.mpm.constitutive.base import common_row, elastic_trial, elastic_trial_tangent, moduli

NAME = "elastic"


@dataclass(frozen=True)
class Params:
    young: float
    poisson: float

    @classmethod
    def from_model(cls, mp):
        return cls(mp.young, mp.poisson)

    def pack(self):
        return common_row(*moduli(self.young, self.poisson))


@njit(cache=True, inline="always")
def update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt):
    sxx, syy, sxy, szz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
    return sxx, syy, sxy, szz, 0.0


@njit(cache=True, inline="always")
def tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T):
    elastic_trial_tangent(prm, sxx, syy, sxy, T)
