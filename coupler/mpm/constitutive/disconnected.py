"""Disconnected (zero-stress) state of a cohesionless granular material below its packing density (Dunatunga &
Kamrin 2015, J. Fluid Mech. 779, sec. 2: sigma = 0 while rho < rho_c; a material that has lost contact carries no
stress and keeps no elastic memory; once re-compacted to rho_c it is stressed again, starting from zero).

Scene option `constitutive = { model = "mohr_coulomb" | "drucker_prager", cohesion = 0, disconnected = true }`
(explicit scheme). rho_c = the material's density, the packing density at which the body is seeded (J = det F = 1),
so a point is disconnected when it is at the apex, sigma = 0 exactly (the cohesionless return gives 0.0 there), and
rho = rho_0 / J < rho_c, i.e. J > 1. Such a point skips the stress update (sigma stays 0, no plastic increment)
until J <= 1. The flag is the stress itself (no extra per-point state).

Why (issue #17, fixed base at h = 1.25 mm): a front point dilated to J ~ 5 by the spreading flow has the density
rho_0 / J with the moduli of the packed material, so its wave speed is sqrt(J) c: at cfl 0.5 of c the explicit step
is unstable for it once J > ~4. Without the option its stress oscillates, the tension cut-off at the apex turns the
oscillation into dilation (J grows faster the larger it is: tests/mpm/test_disconnected.py, a lone point at J = 5
and 20), and the point reached J = 7e30 and put 7e32 N on a node. A point below its packing density carrying the
packed material's stiffness is the error; in the disconnected state it carries none.

`count(prm, mid, s, vol, vol0)` counts the points in that state (summary.json mpm_disconnected_points)."""
from __future__ import annotations

import numpy as np
from numba import njit

from coupler.mpm.constitutive.base import P_DISC


@njit(cache=True, inline="always")
def disconnected(prm, sxx, syy, sxy, szz, J):
    """True when the point is in the disconnected state (module docstring): option on, stress exactly 0, J > 1."""
    return (prm.shape[0] > P_DISC and prm[P_DISC] > 0.0 and J > 1.0 and sxx == 0.0 and syy == 0.0
            and sxy == 0.0 and szz == 0.0)


def count(prm: np.ndarray, mid: np.ndarray, s: np.ndarray, vol: np.ndarray, vol0: np.ndarray) -> np.ndarray:
    """Boolean mask of the points in the disconnected state (the same test as `disconnected`, vectorised)."""
    on = prm[mid, P_DISC] > 0.0 if prm.shape[1] > P_DISC else np.zeros(len(mid), bool)
    return on & (vol > vol0) & np.all(s == 0.0, axis=1)
