"""What every constitutive law shares: the scene-level parameter record, the packed-row layout, the objective
(Jaumann) elastic trial and the equivalent plastic strain increment (definitions in coupler/mpm/materials.py).

A law (one module `coupler/mpm/constitutive/<law>.py`, one line in `constitutive.REGISTRY`) provides
    NAME                          its scene name (`constitutive = { model = NAME, ... }`)
    Params                        frozen dataclass of its parameters, `Params.from_model(ModelParams)` (the scene
                                  record, constitutive/__init__.py), `.pack()`
                                  -> the packed float row of N_PRM entries read by its kernels (slot 0 = law id,
                                  written by the registry; slots P_K, P_G = bulk and shear modulus for every law)
    update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt) -> (sxx, syy, sxy, szz, d_eps_p)
                                  state in (the stress of the start of the step), state out (the stress after the
                                  strain increment (dxx, dyy, gxy = 2 dxy) with spin w = W_xy dt, and the increment
                                  of the per-point history eps_p); numba, pure (no array written)
    tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T)
                                  the consistent (algorithmic) tangent of `update` at that increment: T[r, k] =
                                  d sigma_r / d e_k, r over (xx, yy, xy, zz), k over (dxx, dyy, gxy, w); numba
The per-point state is (sxx, syy, sxy, szz, eps_p) (the kernels' Points.s and Points.eps_p).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

# packed parameter layout (prm[k]); trigonometric constants are evaluated once at packing, not per point and step
P_MODEL, P_K, P_G, P_PHI, P_C, P_PSI, P_SPHI, P_CCOS, P_SPSI, P_APEX, P_ETA, P_XI, P_ETAB, \
    P_DMU, P_I0, P_DG, P_RHOS, P_DISC = range(18)
N_PRM = 18          # P_DISC: 1 = disconnected state below the packing density (constitutive/disconnected.py)


@dataclass(frozen=True)
class RateParams:
    """mu(I) friction (coupler/mpm/materials.py): delta_mu = mu_2 - mu_s, i0 = I_0, grain diameter d [m], grain
    density rho_s [kg/m^3]."""
    delta_mu: float
    i0: float
    grain_diameter: float
    grain_density: float


def moduli(young: float, poisson: float):
    """(K, G) of an isotropic material."""
    return young / (3 * (1 - 2 * poisson)), young / (2 * (1 + poisson))


def dp_plane_strain_match(phi: float, c: float):
    """DP f = sqrt(J2) + eta p - xi c matched to MC in plane strain (de Souza Neto eq. 8.94): returns (eta, xi)."""
    tp = math.tan(phi)
    d = math.sqrt(9.0 + 12.0 * tp * tp)
    return 3.0 * tp / d, 3.0 / d


def common_row(K, G, phi=0.0, c=0.0, psi=0.0, rate=None, disconnected=False):
    """The packed row (slot 0 left 0 for the registry's law id): every law writes the same layout, each reads
    the slots it needs (the layout of the explicit solver before the plug-in split, kept so results are bitwise
    unchanged; P_DISC appended after it)."""
    apex = c / math.tan(phi) if phi > 0.0 else 0.0
    eta, xi = dp_plane_strain_match(phi, c)
    etab, _ = dp_plane_strain_match(psi, c)
    r = rate
    rr = [r.delta_mu, r.i0, r.grain_diameter, r.grain_density] if r is not None else [0.0, 1.0, 0.0, 1.0]
    return [0.0, K, G, phi, c, psi, math.sin(phi), c * math.cos(phi), math.sin(psi), apex, eta, xi, etab] + rr + \
        [1.0 if disconnected else 0.0]


@njit(cache=True, inline="always")
def elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w):
    """Jaumann rotation (W.s - s.W with W = [[0, w], [-w, 0]]) + linear isotropic elastic increment: the trial
    stress (sxx, syy, sxy, szz)."""
    K, G = prm[1], prm[2]
    rxx = 2.0 * w * sxy
    rxy = w * (syy - sxx)
    sxx += rxx
    syy -= rxx
    sxy += rxy
    lam = K - 2.0 * G / 3.0
    ltr = lam * (dxx + dyy)
    sxx += ltr + 2.0 * G * dxx
    syy += ltr + 2.0 * G * dyy
    sxy += G * gxy
    szz += ltr
    return sxx, syy, sxy, szz


@njit(cache=True, inline="always")
def elastic_trial_tangent(prm, sxx, syy, sxy, T):
    """T[r, k] = d trial_r / d e_k of `elastic_trial` (rows xx, yy, xy, zz; columns dxx, dyy, gxy, w)."""
    K, G = prm[1], prm[2]
    lam = K - 2.0 * G / 3.0
    T[:, :] = 0.0
    T[0, 0] = lam + 2.0 * G
    T[0, 1] = lam
    T[0, 3] = 2.0 * sxy
    T[1, 0] = lam
    T[1, 1] = lam + 2.0 * G
    T[1, 3] = -2.0 * sxy
    T[2, 2] = G
    T[2, 3] = syy - sxx
    T[3, 0] = lam
    T[3, 1] = lam


@njit(cache=True, inline="always")
def plastic_increment(G, txx, tyy, txy, tzz, sxx, syy, sxy, szz):
    """Equivalent plastic strain increment sqrt(2/3 de_p:de_p), de_p = dev(trial - returned) / 2G."""
    exx, eyy, exy, ezz = txx - sxx, tyy - syy, txy - sxy, tzz - szz
    em = (exx + eyy + ezz) / 3.0
    exx, eyy, ezz = exx - em, eyy - em, ezz - em
    return math.sqrt((2.0 / 3.0) * (exx * exx + eyy * eyy + ezz * ezz + 2.0 * exy * exy)) / (2.0 * G)


@njit(cache=True, inline="always")
def chain(Dr, Te, T):
    """T = Dr . Te (4 x 4): the tangent of a return Dr = d sigma / d trial after the elastic trial Te."""
    for r in range(4):
        for k in range(4):
            a = 0.0
            for q in range(4):
                a += Dr[r, q] * Te[q, k]
            T[r, k] = a
