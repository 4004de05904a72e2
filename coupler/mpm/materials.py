"""Constitutive laws (tension positive; stress vector s = [xx, yy, xy, zz], plane strain).

Each law: a frozen params dataclass (packed into a float array `prm` for the kernels) + a numba update.
All laws are hypo-elastic with the Jaumann rate, sigma' = C:d + W.sigma - sigma.W (objective), integrated
explicitly; plasticity by return mapping of the elastic trial stress.
  elastic         : linear isotropic
  mohr_coulomb    : perfectly plastic MC (phi, c, psi) in principal stress space with main-plane, edge and apex
                    returns (de Souza Neto, Peric & Owen 2008, Box 8.4-8.5)
  drucker_prager  : perfectly plastic DP matched to MC in plane strain (de Souza Neto et al. 2008, eq. 8.93-8.94)
Optional on mohr_coulomb, `RateParams`: rate-dependent friction after the mu(I) law of Jop, Forterre & Pouliquen
(2006, Nature 441:727, eq. 2): tan phi(I) = tan phi + delta_mu I / (I0 + I), inertial number
I = gamma_dot d / sqrt(p / rho_s), with gamma_dot = sqrt(2 e:e) / dt from the deviatoric total strain increment e
of the step and p = -tr(sigma_trial) / 3 (p <= 0: I -> infinity). phi(I) replaces phi in the yield function of
this step; psi and c stay as given. A regularised elastic-plastic reading of mu(I) (as in Dunatunga & Kamrin 2015,
J. Fluid Mech. 779:483), not a viscous flow law.

History variable `eps_p` (per point): the ACCUMULATED EQUIVALENT (deviatoric, von Mises) PLASTIC STRAIN
    eps_p = sum over steps of sqrt(2/3 de_p : de_p),   de_p = dev(d eps_p) = dev(sigma_trial - sigma) / (2 G)
(de Souza Neto et al. 2008, eq. 6.38 for the definition; the plastic strain increment of an elastic-predictor /
return-mapping step is C^-1 (sigma_trial - sigma), whose deviatoric part is dev(.)/(2G) for isotropic C).
It is the same measure for every law and every return type (plane, edge, apex), counts the out-of-plane (zz)
component, and for a main-plane MC return with psi = 0 equals (2/sqrt 3) x the plastic multiplier. The plastic
multiplier itself (`dgamma`, flow-vector dependent, not comparable between laws) is what `mc_return_principal`
reports; it is not stored per point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

ELASTIC, MOHR_COULOMB, DRUCKER_PRAGER = 0, 1, 2
REGISTRY = {"elastic": ELASTIC, "mohr_coulomb": MOHR_COULOMB, "drucker_prager": DRUCKER_PRAGER}
# packed parameter layout (prm[k]); trigonometric constants are evaluated once here, not per point and step
P_MODEL, P_K, P_G, P_PHI, P_C, P_PSI, P_SPHI, P_CCOS, P_SPSI, P_APEX, P_ETA, P_XI, P_ETAB, \
    P_DMU, P_I0, P_DG, P_RHOS = range(17)
N_PRM = 17


@dataclass(frozen=True)
class RateParams:
    """mu(I) friction (module docstring): delta_mu = mu_2 - mu_s, i0 = I_0, grain diameter d [m], grain density
    rho_s [kg/m^3]."""
    delta_mu: float
    i0: float
    grain_diameter: float
    grain_density: float


@dataclass(frozen=True)
class ModelParams:
    model: str
    young: float
    poisson: float
    friction_angle: float = 0.0   # degrees
    cohesion: float = 0.0
    dilatancy: float = 0.0        # degrees
    rate: RateParams | None = None

    def pack(self) -> np.ndarray:
        G = self.young / (2 * (1 + self.poisson))
        K = self.young / (3 * (1 - 2 * self.poisson))
        phi, psi = math.radians(self.friction_angle), math.radians(self.dilatancy)
        c = self.cohesion
        apex = c / math.tan(phi) if phi > 0.0 else 0.0
        eta, xi = dp_plane_strain_match(phi, c)
        etab, _ = dp_plane_strain_match(psi, c)
        r = self.rate
        rate = [r.delta_mu, r.i0, r.grain_diameter, r.grain_density] if r is not None else [0.0, 1.0, 0.0, 1.0]
        return np.array([REGISTRY[self.model], K, G, phi, c, psi, math.sin(phi), c * math.cos(phi), math.sin(psi),
                         apex, eta, xi, etab] + rate, dtype=np.float64)


def dp_plane_strain_match(phi: float, c: float):
    """DP f = sqrt(J2) + eta p - xi c matched to MC in plane strain (de Souza Neto eq. 8.94): returns (eta, xi)."""
    tp = math.tan(phi)
    d = math.sqrt(9.0 + 12.0 * tp * tp)
    return 3.0 * tp / d, 3.0 / d


@njit(cache=True)
def mc_return(p0, p1, p2, K, G, sphi, ccos, spsi, apex):
    """Return map sorted principal trial stresses p0 >= p1 >= p2 onto the MC surface.
    Returns (s0, s1, s2, dgamma, mode): mode 0 elastic / 1 plane / 2 right edge / 3 left edge / 4 apex (right edge:
    sigma_2 = sigma_3 returned, planes (1,3)+(1,2); left: sigma_1 = sigma_2), dgamma the plastic multiplier sum.
    Flow vector of plane (i,j): N_i = 1 + sin psi, N_j = -1 + sin psi; sigma = sigma_tr - sum_k dgamma_k D N_k
    with D the isotropic elastic matrix in principal space."""
    f = (p0 - p2) + (p0 + p2) * sphi - 2.0 * ccos
    if f <= 0.0:
        return p0, p1, p2, 0.0, 0
    dii = K + 4.0 * G / 3.0
    dij = K - 2.0 * G / 3.0
    # D N for main plane (1,3)
    Na0, Na2 = 1.0 + spsi, -1.0 + spsi
    DNa0 = dii * Na0 + dij * Na2
    DNa1 = dij * (Na0 + Na2)
    DNa2 = dii * Na2 + dij * Na0
    # n_a = df/dsigma = (1 + sphi, 0, -1 + sphi)
    aa = (1.0 + sphi) * DNa0 + (-1.0 + sphi) * DNa2
    dg = f / aa
    s0, s1, s2 = p0 - dg * DNa0, p1 - dg * DNa1, p2 - dg * DNa2
    if s0 >= s1 and s1 >= s2:
        return s0, s1, s2, dg, 1
    # edge return (two planes): right edge shares sigma_1 (planes (1,3),(1,2)), left edge sigma_3 ((1,3),(2,3))
    right = (1.0 - spsi) * p0 - 2.0 * p1 + (1.0 + spsi) * p2 > 0.0
    if right:
        Nb0, Nb1, Nb2 = 1.0 + spsi, -1.0 + spsi, 0.0
        nb0, nb1, nb2 = 1.0 + sphi, -1.0 + sphi, 0.0
        fb = (p0 - p1) + (p0 + p1) * sphi - 2.0 * ccos
    else:
        Nb0, Nb1, Nb2 = 0.0, 1.0 + spsi, -1.0 + spsi
        nb0, nb1, nb2 = 0.0, 1.0 + sphi, -1.0 + sphi
        fb = (p1 - p2) + (p1 + p2) * sphi - 2.0 * ccos
    DNb0 = dii * Nb0 + dij * (Nb1 + Nb2)
    DNb1 = dii * Nb1 + dij * (Nb0 + Nb2)
    DNb2 = dii * Nb2 + dij * (Nb0 + Nb1)
    ab = (1.0 + sphi) * DNb0 + (-1.0 + sphi) * DNb2
    ba = nb0 * DNa0 + nb1 * DNa1 + nb2 * DNa2
    bb = nb0 * DNb0 + nb1 * DNb1 + nb2 * DNb2
    det = aa * bb - ab * ba
    dga = (f * bb - ab * fb) / det
    dgb = (aa * fb - ba * f) / det
    s0 = p0 - dga * DNa0 - dgb * DNb0
    s1 = p1 - dga * DNa1 - dgb * DNb1
    s2 = p2 - dga * DNa2 - dgb * DNb2
    if dga >= 0.0 and dgb >= 0.0 and s0 >= s1 - 1e-12 * abs(s1) and s1 >= s2 - 1e-12 * abs(s2):
        return s0, s1, s2, dga + dgb, 2 if right else 3
    # apex: hydrostatic state at p = c cot(phi) (perfect plasticity, de Souza Neto Box 8.5)
    ptr = (p0 + p1 + p2) / 3.0
    return apex, apex, apex, (ptr - apex) / K if K > 0 else 0.0, 4


def mc_return_principal(p, K, G, phi, c, psi, out):
    """Test helper around `mc_return`: angles in radians, out[0:5] = (s1, s2, s3, dgamma, mode)."""
    apex = c / math.tan(phi) if phi > 0.0 else 0.0
    r = mc_return(float(p[0]), float(p[1]), float(p[2]), K, G, math.sin(phi), c * math.cos(phi), math.sin(psi),
                  apex)
    out[:5] = r


@njit(cache=True)
def rate_friction(prm, sxx, syy, szz, dxx, dyy, gxy, dt):
    """(sin phi(I), c cos phi(I), apex c cot phi(I)) of the mu(I) friction for this step (module docstring)."""
    em = (dxx + dyy) / 3.0
    ee = (dxx - em) ** 2 + (dyy - em) ** 2 + em * em + 0.5 * gxy * gxy
    gdot = math.sqrt(2.0 * ee) / dt if dt > 0.0 else 0.0
    pm = -(sxx + syy + szz) / 3.0
    mu = math.tan(prm[P_PHI])
    if pm <= 0.0:
        mu += prm[P_DMU]
    else:
        inum = gdot * prm[P_DG] / math.sqrt(pm / prm[P_RHOS])
        mu += prm[P_DMU] * inum / (prm[P_I0] + inum)
    sec = math.sqrt(1.0 + mu * mu)
    c = prm[P_C]
    return mu / sec, c / sec, c / mu if mu > 0.0 else 0.0


@njit(cache=True)
def stress_update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt):
    """Jaumann rotation + elastic trial + return for one point. Strain increment (dxx, dyy, gxy = 2 dxy), spin
    increment w = W_xy dt, time step dt (strain rate of the optional mu(I) friction). Returns (sxx, syy, sxy, szz,
    d_eps_p) with d_eps_p the equivalent plastic strain increment sqrt(2/3 de_p:de_p),
    de_p = dev(sigma_trial - sigma) / 2G (module docstring)."""
    model = int(prm[0])
    K, G = prm[1], prm[2]
    # Jaumann: W.s - s.W with W = [[0, w], [-w, 0]]
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
    if model == 0:
        return sxx, syy, sxy, szz, 0.0
    txx, tyy, txy, tzz = sxx, syy, sxy, szz   # trial
    if model == 1:
        # principal in-plane stresses
        cen = 0.5 * (sxx + syy)
        rad = math.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
        sa, sb = cen + rad, cen - rad
        if rad > 0.0:
            c2, s2 = (sxx - syy) / (2.0 * rad), sxy / rad   # cos 2theta, sin 2theta
        else:
            c2, s2 = 1.0, 0.0
        # sort (sa >= sb always); zz position
        if szz >= sa:
            iz = 0
            q0, q1, q2 = szz, sa, sb
        elif szz >= sb:
            iz = 1
            q0, q1, q2 = sa, szz, sb
        else:
            iz = 2
            q0, q1, q2 = sa, sb, szz
        sphi, ccos, apex = prm[P_SPHI], prm[P_CCOS], prm[P_APEX]
        if prm[P_DMU] > 0.0:
            sphi, ccos, apex = rate_friction(prm, sxx, syy, szz, dxx, dyy, gxy, dt)
        r0, r1, r2, dg, mode = mc_return(q0, q1, q2, K, G, sphi, ccos, prm[P_SPSI], apex)
        if mode == 0:
            return sxx, syy, sxy, szz, 0.0
        if iz == 0:
            szz, sa, sb = r0, r1, r2
        elif iz == 1:
            sa, szz, sb = r0, r1, r2
        else:
            sa, sb, szz = r0, r1, r2
        cen = 0.5 * (sa + sb)
        hd = 0.5 * (sa - sb)
        sxx = cen + hd * c2
        syy = cen - hd * c2
        sxy = hd * s2
    else:
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
    # equivalent plastic strain increment from the stress returned (deviatoric part / 2G)
    exx, eyy, exy, ezz = txx - sxx, tyy - syy, txy - sxy, tzz - szz
    em = (exx + eyy + ezz) / 3.0
    exx, eyy, ezz = exx - em, eyy - em, ezz - em
    dep = math.sqrt((2.0 / 3.0) * (exx * exx + eyy * eyy + ezz * ezz + 2.0 * exy * exy)) / (2.0 * G)
    return sxx, syy, sxy, szz, dep


def update_stress(prm, s, de, w, eps_p, tmp=None, dt=1.0):
    """Test helper: updates s[0:4] in place from de = (dxx, dyy, 2 dxy), spin w and time step dt; returns
    eps_p + increment."""
    r = stress_update(prm, float(s[0]), float(s[1]), float(s[2]), float(s[3]), float(de[0]), float(de[1]),
                      float(de[2]), float(w), float(dt))
    s[0], s[1], s[2], s[3] = r[:4]
    return eps_p + r[4]
