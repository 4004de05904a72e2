"""Perfectly plastic Drucker-Prager matched to Mohr-Coulomb in plane strain (de Souza Neto et al. 2008, eq.
8.93-8.94): f = sqrt(J2) + eta p - xi c, plastic potential with eta_bar (dilatancy psi), cone and apex returns.
Tangent: analytic derivative of the cone return (0 at the apex), chained with the elastic trial."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from coupler.mpm.constitutive.base import chain, common_row, elastic_trial, elastic_trial_tangent, moduli, \
    plastic_increment

NAME = "drucker_prager"


@dataclass(frozen=True)
class Params:
    young: float
    poisson: float
    friction_angle: float      # degrees
    cohesion: float
    dilatancy: float           # degrees
    disconnected: bool = False     # constitutive/disconnected.py (explicit scheme, cohesion = 0)

    @classmethod
    def from_model(cls, mp):
        return cls(mp.young, mp.poisson, mp.friction_angle, mp.cohesion, mp.dilatancy, mp.disconnected)

    def pack(self):
        K, G = moduli(self.young, self.poisson)
        return common_row(K, G, math.radians(self.friction_angle), self.cohesion, math.radians(self.dilatancy),
                          disconnected=self.disconnected)


@njit(cache=True, inline="always")
def update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt):
    K, G = prm[1], prm[2]
    sxx, syy, sxy, szz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
    txx, tyy, txy, tzz = sxx, syy, sxy, szz   # trial
    eta, xi, etab = prm[10], prm[11], prm[12]
    c = prm[4]
    pm = (sxx + syy + szz) / 3.0
    dxx_, dyy_, dzz_ = sxx - pm, syy - pm, szz - pm
    q = math.sqrt(0.5 * (dxx_ * dxx_ + dyy_ * dyy_ + dzz_ * dzz_) + sxy * sxy)
    f = q + eta * pm - xi * c
    if f <= 0.0:
        return sxx, syy, sxy, szz, 0.0
    dg = f / (G + K * eta * etab)
    if q - G * dg >= 0.0:
        fac = (q - G * dg) / q
        pm = pm - K * etab * dg
    else:  # apex
        fac = 0.0
        pm = xi * c / eta if eta > 0.0 else 0.0
    sxx, syy, szz, sxy = pm + fac * dxx_, pm + fac * dyy_, pm + fac * dzz_, fac * sxy
    return sxx, syy, sxy, szz, plastic_increment(G, txx, tyy, txy, tzz, sxx, syy, sxy, szz)


@njit(cache=True)
def tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T):
    K, G = prm[1], prm[2]
    Te = np.empty((4, 4))
    elastic_trial_tangent(prm, sxx, syy, sxy, Te)
    txx, tyy, txy, tzz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
    eta, xi, etab = prm[10], prm[11], prm[12]
    c = prm[4]
    pm = (txx + tyy + tzz) / 3.0
    dev = np.array([txx - pm, tyy - pm, txy, tzz - pm])     # deviator, xy component at index 2
    q = math.sqrt(0.5 * (dev[0] ** 2 + dev[1] ** 2 + dev[3] ** 2) + txy * txy)
    f = q + eta * pm - xi * c
    if f <= 0.0:
        T[:, :] = Te
        return
    Aden = G + K * eta * etab
    dg = f / Aden
    Dr = np.zeros((4, 4))
    if q - G * dg < 0.0:     # apex: constant stress
        T[:, :] = 0.0
        return
    fac = (q - G * dg) / q
    normal = np.array([1.0, 1.0, 0.0, 1.0])
    dq = np.empty(4)
    for k in range(4):
        dq[k] = dev[k] / q if k == 2 else dev[k] / (2.0 * q)
    for k in range(4):
        dpm = normal[k] / 3.0
        ddg = (dq[k] + eta * dpm) / Aden
        dfac = G * dg * dq[k] / (q * q) - G * ddg / q
        dpmn = dpm - K * etab * ddg
        for r in range(4):
            if r == 2:
                Dr[r, k] = dfac * txy + (fac if k == 2 else 0.0)
            else:
                ddev = ((1.0 if r == k else 0.0) - 1.0 / 3.0) if normal[k] > 0.0 else 0.0
                Dr[r, k] = dpmn + dfac * dev[r] + fac * ddev
    chain(Dr, Te, T)
