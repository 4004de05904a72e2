"""Constitutive laws (tension positive; stress vector s = [xx, yy, xy, zz], plane strain).

Each law: a frozen params dataclass (packed into a float array `prm` for the kernels) + a numba update.
All laws are hypo-elastic with the Jaumann rate, sigma' = C:d + W.sigma - sigma.W (objective), integrated
explicitly; plasticity by return mapping of the elastic trial stress.
  elastic         : linear isotropic
  mohr_coulomb    : perfectly plastic MC (phi, c, psi) in principal stress space with main-plane, edge and apex
                    returns (de Souza Neto, Peric & Owen 2008, Box 8.4-8.5)
  drucker_prager  : perfectly plastic DP matched to MC in plane strain (de Souza Neto et al. 2008, eq. 8.93-8.94)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

ELASTIC, MOHR_COULOMB, DRUCKER_PRAGER = 0, 1, 2
REGISTRY = {"elastic": ELASTIC, "mohr_coulomb": MOHR_COULOMB, "drucker_prager": DRUCKER_PRAGER}


@dataclass(frozen=True)
class ModelParams:
    model: str
    young: float
    poisson: float
    friction_angle: float = 0.0   # degrees
    cohesion: float = 0.0
    dilatancy: float = 0.0        # degrees

    def pack(self) -> np.ndarray:
        G = self.young / (2 * (1 + self.poisson))
        K = self.young / (3 * (1 - 2 * self.poisson))
        phi, psi = math.radians(self.friction_angle), math.radians(self.dilatancy)
        return np.array([REGISTRY[self.model], K, G, phi, self.cohesion, psi], dtype=np.float64)


def dp_plane_strain_match(phi: float, c: float):
    """DP f = sqrt(J2) + eta p - xi c matched to MC in plane strain (de Souza Neto eq. 8.94): returns (eta, xi)."""
    tp = math.tan(phi)
    d = math.sqrt(9.0 + 12.0 * tp * tp)
    return 3.0 * tp / d, 3.0 / d


@njit(cache=True, inline="always")
def _mc_f(s1, s3, sphi, ccos):
    return (s1 - s3) + (s1 + s3) * sphi - 2.0 * ccos


@njit(cache=True)
def mc_return_principal(p, K, G, phi, c, psi, out):
    """Return map sorted principal trial stresses p[0] >= p[1] >= p[2] onto the MC surface.
    Writes out[0:3] (sorted), out[3] = plastic multiplier sum, out[4] = 0 elastic / 1 plane / 2 right edge /
    3 left edge / 4 apex (right edge: sigma_2 = sigma_3 returned, planes (1,3)+(1,2); left: sigma_1 = sigma_2). Flow vector of plane (i,j): N_i = 1 + sin psi, N_j = -1 + sin psi; stress update
    sigma = sigma_tr - sum_k dgamma_k D N_k with D the isotropic elastic matrix in principal space."""
    sphi, spsi = math.sin(phi), math.sin(psi)
    ccos = c * math.cos(phi)
    dii = K + 4.0 * G / 3.0
    dij = K - 2.0 * G / 3.0
    f = _mc_f(p[0], p[2], sphi, ccos)
    if f <= 0.0:
        out[0], out[1], out[2], out[3], out[4] = p[0], p[1], p[2], 0.0, 0.0
        return
    # D N for main plane (1,3)
    Na0, Na1, Na2 = 1.0 + spsi, 0.0, -1.0 + spsi
    DNa0 = dii * Na0 + dij * (Na1 + Na2)
    DNa1 = dii * Na1 + dij * (Na0 + Na2)
    DNa2 = dii * Na2 + dij * (Na0 + Na1)
    # n_a = df/dsigma = (1 + sphi, 0, -1 + sphi)
    aa = (1.0 + sphi) * DNa0 + (-1.0 + sphi) * DNa2
    dg = f / aa
    s0, s1, s2 = p[0] - dg * DNa0, p[1] - dg * DNa1, p[2] - dg * DNa2
    if s0 >= s1 and s1 >= s2:
        out[0], out[1], out[2], out[3], out[4] = s0, s1, s2, dg, 1.0
        return
    # edge return (two planes): right edge shares sigma_1 (planes (1,3),(1,2)), left edge sigma_3 ((1,3),(2,3))
    right = (1.0 - spsi) * p[0] - 2.0 * p[1] + (1.0 + spsi) * p[2] > 0.0
    if right:
        Nb0, Nb1, Nb2 = 1.0 + spsi, -1.0 + spsi, 0.0
        nb0, nb1, nb2 = 1.0 + sphi, -1.0 + sphi, 0.0
        fb = (p[0] - p[1]) + (p[0] + p[1]) * sphi - 2.0 * ccos
    else:
        Nb0, Nb1, Nb2 = 0.0, 1.0 + spsi, -1.0 + spsi
        nb0, nb1, nb2 = 0.0, 1.0 + sphi, -1.0 + sphi
        fb = (p[1] - p[2]) + (p[1] + p[2]) * sphi - 2.0 * ccos
    DNb0 = dii * Nb0 + dij * (Nb1 + Nb2)
    DNb1 = dii * Nb1 + dij * (Nb0 + Nb2)
    DNb2 = dii * Nb2 + dij * (Nb0 + Nb1)
    ab = (1.0 + sphi) * DNb0 + (-1.0 + sphi) * DNb2
    ba = nb0 * DNa0 + nb1 * DNa1 + nb2 * DNa2
    bb = nb0 * DNb0 + nb1 * DNb1 + nb2 * DNb2
    det = aa * bb - ab * ba
    dga = (f * bb - ab * fb) / det
    dgb = (aa * fb - ba * f) / det
    s0 = p[0] - dga * DNa0 - dgb * DNb0
    s1 = p[1] - dga * DNa1 - dgb * DNb1
    s2 = p[2] - dga * DNa2 - dgb * DNb2
    if dga >= 0.0 and dgb >= 0.0 and s0 >= s1 - 1e-12 * abs(s1) and s1 >= s2 - 1e-12 * abs(s2):
        out[0], out[1], out[2], out[3], out[4] = s0, s1, s2, dga + dgb, 2.0 if right else 3.0
        return
    # apex: hydrostatic state at p = c cot(phi) (perfect plasticity, de Souza Neto Box 8.5)
    pa = c / math.tan(phi) if phi > 0.0 else 0.0
    ptr = (p[0] + p[1] + p[2]) / 3.0
    out[0], out[1], out[2] = pa, pa, pa
    out[3] = (ptr - pa) / K if K > 0 else 0.0
    out[4] = 4.0


@njit(cache=True)
def update_stress(prm, s, de, w, eps_p, tmp):
    """Jaumann rotation + elastic trial + return. s[4] stress (in/out), de = (dxx, dyy, 2*dxy) strain increment,
    w = spin increment W_xy dt. Returns accumulated equivalent plastic strain."""
    model = int(prm[0])
    K, G = prm[1], prm[2]
    sxx, syy, sxy, szz = s[0], s[1], s[2], s[3]
    # Jaumann: W.s - s.W with W = [[0, w], [-w, 0]]
    rxx = 2.0 * w * sxy
    ryy = -2.0 * w * sxy
    rxy = w * (syy - sxx)
    sxx += rxx
    syy += ryy
    sxy += rxy
    lam = K - 2.0 * G / 3.0
    tr = de[0] + de[1]
    sxx += lam * tr + 2.0 * G * de[0]
    syy += lam * tr + 2.0 * G * de[1]
    sxy += G * de[2]
    szz += lam * tr
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
            tmp[0], tmp[1], tmp[2] = szz, sa, sb
        elif szz >= sb:
            iz = 1
            tmp[0], tmp[1], tmp[2] = sa, szz, sb
        else:
            iz = 2
            tmp[0], tmp[1], tmp[2] = sa, sb, szz
        mc_return_principal(tmp, K, G, prm[3], prm[4], prm[5], tmp[3:8])
        if tmp[7] > 0.0:
            r = tmp[3:6]
            if iz == 0:
                szz, sa, sb = r[0], r[1], r[2]
            elif iz == 1:
                sa, szz, sb = r[0], r[1], r[2]
            else:
                sa, sb, szz = r[0], r[1], r[2]
            cen = 0.5 * (sa + sb)
            hd = 0.5 * (sa - sb)
            sxx = cen + hd * c2
            syy = cen - hd * c2
            sxy = hd * s2
            eps_p += tmp[6]
    elif model == 2:
        tp = math.tan(prm[3])
        d = math.sqrt(9.0 + 12.0 * tp * tp)
        eta, xi = 3.0 * tp / d, 3.0 / d
        tq = math.tan(prm[5])
        dq = math.sqrt(9.0 + 12.0 * tq * tq)
        etab = 3.0 * tq / dq
        c = prm[4]
        pm = (sxx + syy + szz) / 3.0
        dxx, dyy, dzz = sxx - pm, syy - pm, szz - pm
        j2 = 0.5 * (dxx * dxx + dyy * dyy + dzz * dzz) + sxy * sxy
        q = math.sqrt(j2)
        f = q + eta * pm - xi * c
        if f > 0.0:
            dg = f / (G + K * eta * etab)
            if q - G * dg >= 0.0:
                fac = (q - G * dg) / q
                pm = pm - K * etab * dg
            else:  # apex
                fac = 0.0
                pm = xi * c / eta if eta > 0.0 else 0.0
                dg = q / G
            sxx, syy, szz, sxy = pm + fac * dxx, pm + fac * dyy, pm + fac * dzz, fac * sxy
            eps_p += dg
    s[0], s[1], s[2], s[3] = sxx, syy, sxy, szz
    return eps_p
