"""Perfectly plastic Mohr-Coulomb (phi, c, psi) in principal stress space with main-plane, edge and apex returns
(de Souza Neto, Peric & Owen 2008, Box 8.4-8.5), optional mu(I) rate-dependent friction (Jop et al. 2006; the
definitions are in coupler/mpm/materials.py).

Tangent: the return of each mode is linear in the sorted principal trial stresses (constant matrix A: I - DN n^T /
n.DN for the main plane, the two-plane version for an edge, 0 at the apex), the in-plane principal directions are
those of the trial stress; the consistent tangent is A mapped through the derivative of the spectral decomposition
(angle of the principal axes included), chained with the elastic trial (Jaumann rotation included). With mu(I)
the friction angle depends on the strain increment too: the tangent is then the central finite difference of
`update` (step 1e-7 max(|d eps|, 1e-5)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from coupler.mpm.constitutive.base import (P_APEX, P_C, P_CCOS, P_DG, P_DMU, P_I0, P_PHI, P_RHOS, P_SPHI, P_SPSI,
                                           RateParams, common_row, elastic_trial, elastic_trial_tangent,
                                           moduli, plastic_increment)

NAME = "mohr_coulomb"


@dataclass(frozen=True)
class Params:
    young: float
    poisson: float
    friction_angle: float      # degrees
    cohesion: float
    dilatancy: float           # degrees
    rate: RateParams | None = None
    disconnected: bool = False     # constitutive/disconnected.py (explicit scheme, cohesion = 0)

    @classmethod
    def from_model(cls, mp):
        return cls(mp.young, mp.poisson, mp.friction_angle, mp.cohesion, mp.dilatancy, mp.rate, mp.disconnected)

    def pack(self):
        K, G = moduli(self.young, self.poisson)
        return common_row(K, G, math.radians(self.friction_angle), self.cohesion, math.radians(self.dilatancy),
                          self.rate, self.disconnected)


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
    # the two stresses an edge return makes equal differ by the round-off of the trial stresses, so the order is
    # checked to 1e-12 of the trial's scale (not of the returned stresses: a 632 Pa trial shear returned to 0.2 Pa
    # gave s1 - s2 = -3e-13 and fell to the apex, stress 0, multiplier < 0; found by hypothesis)
    tol = 1e-12 * max(abs(p0), abs(p2))
    if dga >= 0.0 and dgb >= 0.0 and s0 >= s1 - tol and s1 >= s2 - tol:
        return s0, s1, s2, dga + dgb, 2 if right else 3
    # apex: hydrostatic state at p = c cot(phi) (perfect plasticity, de Souza Neto Box 8.5)
    ptr = (p0 + p1 + p2) / 3.0
    return apex, apex, apex, (ptr - apex) / K if K > 0 else 0.0, 4


@njit(cache=True)
def rate_friction(prm, sxx, syy, szz, dxx, dyy, gxy, dt):
    """(sin phi(I), c cos phi(I), apex c cot phi(I)) of the mu(I) friction for this step (materials.py)."""
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


@njit(cache=True, inline="always")
def update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt):
    K, G = prm[1], prm[2]
    sxx, syy, sxy, szz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
    txx, tyy, txy, tzz = sxx, syy, sxy, szz   # trial
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
    return sxx, syy, sxy, szz, plastic_increment(G, txx, tyy, txy, tzz, sxx, syy, sxy, szz)


@njit(cache=True)
def _fd_tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T):
    # a plastic return that lands on the apex takes the apex tangent (0, perfect plasticity), as in `tangent`: the
    # differences below would straddle the cone's tip (found by hypothesis: sxy = 1 Pa, szz = -1e-9 Pa, zero
    # strain increment, c = 0: half the elastic tangent from the compressed side)
    r = update(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt)
    if r[4] > 0.0:
        txx, tyy, txy, tzz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
        apex = rate_friction(prm, txx, tyy, tzz, dxx, dyy, gxy, dt)[2]
        scale = max(abs(txx), abs(tyy), abs(txy), abs(tzz), abs(apex))
        if max(abs(r[0] - apex), abs(r[1] - apex), abs(r[2]), abs(r[3] - apex)) <= 1e-12 * scale:
            T[:, :] = 0.0
            return
    e = np.array([dxx, dyy, gxy, w])
    hstep = 1e-7 * max(abs(dxx), abs(dyy), abs(gxy), abs(w), 1e-5)
    for k in range(4):
        ep = e.copy()
        em = e.copy()
        ep[k] += hstep
        em[k] -= hstep
        a = update(prm, sxx, syy, sxy, szz, ep[0], ep[1], ep[2], ep[3], dt)
        b = update(prm, sxx, syy, sxy, szz, em[0], em[1], em[2], em[3], dt)
        T[0, k] = (a[0] - b[0]) / (2 * hstep)
        T[1, k] = (a[1] - b[1]) / (2 * hstep)
        T[2, k] = (a[2] - b[2]) / (2 * hstep)
        T[3, k] = (a[3] - b[3]) / (2 * hstep)


@njit(cache=True, inline="always")
def _return_rows(mode, K, G, sphi, spsi, iz):
    """d s_i / d p_j of `mc_return` in the given mode (piecewise linear in the sorted trial stresses: I - DN n^T /
    n.DN for a plane, the two-plane version for an edge, 0 at the apex) as nine scalars, reordered from the sorted
    triple to (sa, sb, szz): B[u][v] = A[pos[u], pos[v]], pos the places of sa, sb, szz in the sorted triple (iz =
    the place of szz). On the stack: the scratch arrays of the tangent before (a 3 x 3 matrix, np.zeros((6, 4, 4)))
    cost about half of it (104 -> 57 ns per plastic point, results bitwise the same)."""
    if mode == 4:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    dii = K + 4.0 * G / 3.0
    dij = K - 2.0 * G / 3.0
    Na0, Na2 = 1.0 + spsi, -1.0 + spsi
    D0, D1, D2 = dii * Na0 + dij * Na2, dij * (Na0 + Na2), dii * Na2 + dij * Na0
    n0, n1, n2 = 1.0 + sphi, 0.0, -1.0 + sphi
    aa = n0 * D0 + n2 * D2
    if mode == 1:
        a00, a01, a02 = 1.0 - D0 * n0 / aa, 0.0 - D0 * n1 / aa, 0.0 - D0 * n2 / aa
        a10, a11, a12 = 0.0 - D1 * n0 / aa, 1.0 - D1 * n1 / aa, 0.0 - D1 * n2 / aa
        a20, a21, a22 = 0.0 - D2 * n0 / aa, 0.0 - D2 * n1 / aa, 1.0 - D2 * n2 / aa
    else:
        if mode == 2:
            Nb0, Nb1, Nb2 = 1.0 + spsi, -1.0 + spsi, 0.0
            m0, m1, m2 = 1.0 + sphi, -1.0 + sphi, 0.0
        else:
            Nb0, Nb1, Nb2 = 0.0, 1.0 + spsi, -1.0 + spsi
            m0, m1, m2 = 0.0, 1.0 + sphi, -1.0 + sphi
        E0, E1, E2 = (dii * Nb0 + dij * (Nb1 + Nb2), dii * Nb1 + dij * (Nb0 + Nb2), dii * Nb2 + dij * (Nb0 + Nb1))
        ab = n0 * E0 + n2 * E2
        ba = m0 * D0 + m1 * D1 + m2 * D2
        bb = m0 * E0 + m1 * E1 + m2 * E2
        det = aa * bb - ab * ba
        p0, p1, p2 = bb * n0 - ab * m0, bb * n1 - ab * m1, bb * n2 - ab * m2
        q0, q1, q2 = aa * m0 - ba * n0, aa * m1 - ba * n1, aa * m2 - ba * n2
        a00 = 1.0 - (D0 * p0 / det + E0 * q0 / det)
        a01 = 0.0 - (D0 * p1 / det + E0 * q1 / det)
        a02 = 0.0 - (D0 * p2 / det + E0 * q2 / det)
        a10 = 0.0 - (D1 * p0 / det + E1 * q0 / det)
        a11 = 1.0 - (D1 * p1 / det + E1 * q1 / det)
        a12 = 0.0 - (D1 * p2 / det + E1 * q2 / det)
        a20 = 0.0 - (D2 * p0 / det + E2 * q0 / det)
        a21 = 0.0 - (D2 * p1 / det + E2 * q1 / det)
        a22 = 1.0 - (D2 * p2 / det + E2 * q2 / det)
    if iz == 0:     # pos = (1, 2, 0)
        return a11, a12, a10, a21, a22, a20, a01, a02, a00
    if iz == 1:     # pos = (0, 2, 1)
        return a00, a02, a01, a20, a22, a21, a10, a12, a11
    return a00, a01, a02, a10, a11, a12, a20, a21, a22


@njit(cache=True, inline="always")
def tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T):
    if prm[P_DMU] > 0.0:
        _fd_tangent(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt, T)
        return
    K, G = prm[1], prm[2]
    txx, tyy, txy, tzz = elastic_trial(prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w)
    cen = 0.5 * (txx + tyy)
    a = 0.5 * (txx - tyy)
    rad = math.sqrt(a * a + txy * txy)
    sa, sb = cen + rad, cen - rad
    if rad > 0.0:
        c2, s2 = a / rad, txy / rad
    else:
        c2, s2 = 1.0, 0.0
    if tzz >= sa:
        iz = 0
        q0, q1, q2 = tzz, sa, sb
    elif tzz >= sb:
        iz = 1
        q0, q1, q2 = sa, tzz, sb
    else:
        iz = 2
        q0, q1, q2 = sa, sb, tzz
    apex = prm[P_APEX]
    r0, r1, r2, dg, mode = mc_return(q0, q1, q2, K, G, prm[P_SPHI], prm[P_CCOS], prm[P_SPSI], apex)
    if mode == 0:
        elastic_trial_tangent(prm, sxx, syy, sxy, T)
        return
    if mode != 4 and max(abs(r0 - apex), abs(r1 - apex), abs(r2 - apex)) <= 1e-12 * max(abs(q0), abs(q2),
                                                                                         abs(apex)):
        # a plane / edge return that lands on the apex (trial mean stress at the apex, c = 0: every mode meets
        # there) takes the apex tangent, the one its neighbours within round-off get (found by hypothesis:
        # sxy = 1 Pa, zero strain increment, phi 19.8 deg, c = 0)
        mode = 4
    # B = d(ra, rb, rz) / d(sa, sb, szz): the return matrix of the mode in the order (sa, sb, szz)
    b00, b01, b02, b10, b11, b12, b20, b21, b22 = _return_rows(mode, K, G, prm[P_SPHI], prm[P_SPSI], iz)
    if iz == 0:
        ra, rb = r1, r2
    elif iz == 1:
        ra, rb = r0, r2
    else:
        ra, rb = r0, r1
    # d(sa, sb, szz) / d(txx, tyy, txy, tzz) = [[1/2 + c2/2, 1/2 - c2/2, s2, 0], [1/2 - c2/2, 1/2 + c2/2, -s2, 0],
    # [0, 0, 0, 1]]; Jr = B of it: d(ra, rb, rz) / d trial, columns txx, tyy, txy, tzz
    hp, hm = 0.5 + 0.5 * c2, 0.5 - 0.5 * c2
    ja0, ja1, ja2, ja3 = b00 * hp + b01 * hm, b00 * hm + b01 * hp, b00 * s2 + b01 * -s2, b02
    jb0, jb1, jb2, jb3 = b10 * hp + b11 * hm, b10 * hm + b11 * hp, b10 * s2 + b11 * -s2, b12
    jz0, jz1, jz2, jz3 = b20 * hp + b21 * hm, b20 * hm + b21 * hp, b20 * s2 + b21 * -s2, b22
    # hd d(c2, s2) / d trial: d c2 / d a = s2^2 / rad, d c2 / d txy = -c2 s2 / rad, d s2 / d a = -c2 s2 / rad,
    # d s2 / d txy = c2^2 / rad, taken with the factor hd / rad (bounded: the returned in-plane radius hd vanishes
    # with the trial one), so a trial radius whose cube underflows (2e-130 Pa) still gives a finite tangent
    hd = 0.5 * (ra - rb)
    dc0 = dc1 = dc2 = ds0 = ds1 = ds2 = 0.0
    if rad > 0.0:
        q = hd / rad
        dca, dcb = q * s2 * s2, -q * c2 * s2
        dsa, dsb = -q * c2 * s2, q * c2 * c2
        dc0, dc1, dc2 = 0.5 * dca, -0.5 * dca, dcb
        ds0, ds1, ds2 = 0.5 * dsa, -0.5 * dsa, dsb
    # Dr = d sigma / d trial (rows xx, yy, xy, zz): sigma_xx = cen + hd c2, sigma_yy = cen - hd c2, sigma_xy = hd s2
    dcen, dhd = 0.5 * (ja0 + jb0), 0.5 * (ja0 - jb0)
    x0, y0, z0, w0 = dcen + dhd * c2 + dc0, dcen - dhd * c2 - dc0, dhd * s2 + ds0, jz0
    dcen, dhd = 0.5 * (ja1 + jb1), 0.5 * (ja1 - jb1)
    x1, y1, z1, w1 = dcen + dhd * c2 + dc1, dcen - dhd * c2 - dc1, dhd * s2 + ds1, jz1
    dcen, dhd = 0.5 * (ja2 + jb2), 0.5 * (ja2 - jb2)
    x2, y2, z2, w2 = dcen + dhd * c2 + dc2, dcen - dhd * c2 - dc2, dhd * s2 + ds2, jz2
    dcen, dhd = 0.5 * (ja3 + jb3), 0.5 * (ja3 - jb3)
    x3, y3, z3, w3 = dcen + dhd * c2, dcen - dhd * c2, dhd * s2, jz3
    # T = Dr . Te, Te = elastic_trial_tangent (rows xx, yy, xy, zz: [l2g, lam, 0, 2 sxy], [lam, l2g, 0, -2 sxy],
    # [0, 0, G, syy - sxx], [lam, lam, 0, 0]; base.chain's product with the zero entries of Te left out)
    lam = K - 2.0 * G / 3.0
    l2g = lam + 2.0 * G
    e03, e13, e23 = 2.0 * sxy, -2.0 * sxy, syy - sxx
    T[0, 0], T[0, 1], T[0, 2], T[0, 3] = x0 * l2g + x1 * lam + x3 * lam, x0 * lam + x1 * l2g + x3 * lam, \
        x2 * G, x0 * e03 + x1 * e13 + x2 * e23
    T[1, 0], T[1, 1], T[1, 2], T[1, 3] = y0 * l2g + y1 * lam + y3 * lam, y0 * lam + y1 * l2g + y3 * lam, \
        y2 * G, y0 * e03 + y1 * e13 + y2 * e23
    T[2, 0], T[2, 1], T[2, 2], T[2, 3] = z0 * l2g + z1 * lam + z3 * lam, z0 * lam + z1 * l2g + z3 * lam, \
        z2 * G, z0 * e03 + z1 * e13 + z2 * e23
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = w0 * l2g + w1 * lam + w3 * lam, w0 * lam + w1 * l2g + w3 * lam, \
        w2 * G, w0 * e03 + w1 * e13 + w2 * e23
