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
The laws live in coupler/mpm/constitutive/ (one module each, REGISTRY there); this module keeps the names the
rest of the code and the tests import.
"""

from __future__ import annotations

import math

from coupler.mpm.constitutive import LAW_ID as REGISTRY, N_PRM, stress_tangent, stress_update  # noqa: F401
from coupler.mpm.constitutive.base import (P_APEX, P_C, P_CCOS, P_DG, P_DMU, P_ETA, P_ETAB, P_G, P_I0,  # noqa: F401
                                           P_K, P_MODEL, P_PHI, P_PSI, P_RHOS, P_SPHI, P_SPSI, P_XI,
                                           RateParams, dp_plane_strain_match)
from coupler.mpm.constitutive import ModelParams  # noqa: F401
from coupler.mpm.constitutive.mohr_coulomb import mc_return, rate_friction  # noqa: F401

ELASTIC, MOHR_COULOMB, DRUCKER_PRAGER = REGISTRY["elastic"], REGISTRY["mohr_coulomb"], REGISTRY["drucker_prager"]


def mc_return_principal(p, K, G, phi, c, psi, out):
    """Test helper around `mc_return`: angles in radians, out[0:5] = (s1, s2, s3, dgamma, mode)."""
    apex = c / math.tan(phi) if phi > 0.0 else 0.0
    r = mc_return(float(p[0]), float(p[1]), float(p[2]), K, G, math.sin(phi), c * math.cos(phi), math.sin(psi),
                  apex)
    out[:5] = r


def update_stress(prm, s, de, w, eps_p, tmp=None, dt=1.0):
    """Test helper: updates s[0:4] in place from de = (dxx, dyy, 2 dxy), spin w and time step dt; returns
    eps_p + increment."""
    r = stress_update(prm, float(s[0]), float(s[1]), float(s[2]), float(s[3]), float(de[0]), float(de[1]),
                      float(de[2]), float(w), float(dt))
    s[0], s[1], s[2], s[3] = r[:4]
    return eps_p + r[4]
