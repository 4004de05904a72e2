"""The composed contact law: normal + damping + tangential + rolling sub-models, one table row per material pair
and one inlined function per contact (the same for sphere-sphere, sphere-plane and sphere-mesh contacts).

    vn   = v . n  (> 0 approaching; v = contact-point velocity of i relative to j, n from i towards j)
    F_n  = max(0, F_el(d) + 2 beta sqrt(S m*) vn)                       (normal.py, damping.py)
    F_t  = tangential(S_t, beta, mu, F_n, v_t, xi)                      (tangential.py)
    M    = rolling(mu_r, k_r, S_t, R*, F_n, w_i - w_j, M_old)           (rolling.py)
    force on i: -F_n n + F_t, rolling torque on i: M (on j: -F, -M)

Cluster contacts: m* uses the damping mass of each member sphere: the cluster's body mass ("body", LIGGGHTS
multisphere) or the member sphere's own mass ("sphere", YADE clumps).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from coupler.dem.contact.damping import DAMPING
from coupler.dem.contact.normal import effective_shear, effective_young, normal_force
from coupler.contact_models import NORMAL, ROLLING, TANGENTIAL
from coupler.dem.contact.rolling import rolling_torque
from coupler.dem.contact.tangential import tangential_force

# law table columns (one row per material pair). A scene whose laws are all Hertz without rolling resistance gets
# the compact table of the first NLAW_HM columns (and the kernels the narrower per-contact state rows).
E_STAR, G_STAR, BETA, MU, HIST, NORMAL_ID, KN, KT_RATIO, ROLL_ID, MU_R, K_ROLL = range(11)
NLAW = 11
NLAW_HM = 5


def damping_ratio(law) -> float:
    normal = getattr(law, "normal", "hertz")
    if law.damping not in DAMPING:
        raise ValueError(f"unknown damping mode {law.damping!r}")
    return DAMPING[law.damping](law.restitution, normal)


def law_row(a, b, law) -> np.ndarray:
    """One table row for materials a, b and their ContactLaw (columns above)."""
    normal = getattr(law, "normal", "hertz")
    rolling = getattr(law, "rolling", "none")
    kroll = getattr(law, "rolling_stiffness", None)
    return np.array([effective_young(a, b), effective_shear(a, b), damping_ratio(law), law.friction,
                     float(TANGENTIAL[law.tangential].code), float(NORMAL[normal].code),
                     float(getattr(law, "normal_stiffness", 0.0)), float(getattr(law, "tangential_ratio", 0.0)),
                     float(ROLLING[rolling].code), float(getattr(law, "rolling_coefficient", 0.0)),
                     -1.0 if kroll is None else float(kroll)])


def law_table(materials: list, laws: dict) -> np.ndarray:
    """(nmat, nmat, NLAW) table. laws: dict[(a, b)] -> ContactLaw (keys sorted as coupler.scene.pair_key)."""
    n = len(materials)
    hm = all(getattr(l, "normal", "hertz") == "hertz" and getattr(l, "rolling", "none") == "none"
             for l in laws.values())
    tab = np.zeros((n, n, NLAW_HM if hm else NLAW))
    for i, a in enumerate(materials):
        for j, b in enumerate(materials):
            key = (a.name, b.name) if a.name <= b.name else (b.name, a.name)
            if key not in laws or (math.isinf(a.young) and math.isinf(b.young)):
                tab[i, j, :] = np.nan  # never touched (finish_dem: every pair that can touch has a law; two rigid
                continue               # wall copies, E = inf, are two walls)
            tab[i, j] = law_row(a, b, laws[key])[:tab.shape[2]]
    return tab


@njit(cache=True, inline="always")
def law_extra(table, mi, mj, hm):
    """Sub-model columns of a law-table row: (normal, k_n, k_t/k_n, rolling, mu_r, k_r); hm: the table is the
    compact one (Hertz without rolling; pass it as a constant so that the sub-model branches compile away)."""
    if not hm:
        return (table[mi, mj, NORMAL_ID], table[mi, mj, KN], table[mi, mj, KT_RATIO], table[mi, mj, ROLL_ID],
                table[mi, mj, MU_R], table[mi, mj, K_ROLL])
    return 0.0, 0.0, 0.0, 0.0, 0.0, -1.0


@njit(cache=True, inline="always")
def contact_force(delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, rstar, mstar, estar, gstar, beta, mu, hist,
                  normal, kn, kt_ratio, roll, mur, kroll, dt, x0, x1, x2, m0, m1, m2):
    """Contact force on body i for overlap `delta`, unit normal n (from i towards j), contact-point velocity
    v = v_i - v_j and relative angular velocity w = w_i - w_j; (x0, x1, x2) the tangential history xi,
    (m0, m1, m2) the rolling state.

    Returns (fx, fy, fz, fn, ft, elastic_energy, xi0, xi1, xi2, mx, my, mz, m0, m1, m2): force and rolling
    torque on i (on j the opposite), new states. Scalars only, so it inlines into the loops without array
    reference counting.
    """
    sn, st, fel, e_n = normal_force(normal, delta, rstar, estar, gstar, kn, kt_ratio)
    vn = vx * nx + vy * ny + vz * nz                    # > 0 approaching
    fn = fel + 2.0 * beta * math.sqrt(sn * mstar) * vn
    if fn < 0.0:
        fn = 0.0
    vtx = vx - vn * nx
    vty = vy - vn * ny
    vtz = vz - vn * nz
    ftx, fty, ftz, e_t, x0, x1, x2 = tangential_force(hist, st, beta, mstar, fn, mu, nx, ny, nz, vtx, vty, vtz,
                                                      dt, x0, x1, x2)
    mx, my, mz, e_r, m0, m1, m2 = rolling_torque(roll, mur, kroll, st, rstar, fn, nx, ny, nz, wx, wy, wz, dt,
                                                 m0, m1, m2)
    fx = -fn * nx + ftx
    fy = -fn * ny + fty
    fz = -fn * nz + ftz
    ft = math.sqrt(ftx * ftx + fty * fty + ftz * ftz)
    return fx, fy, fz, fn, ft, e_n + e_t + e_r, x0, x1, x2, mx, my, mz, m0, m1, m2


def time_limits(scene, catalogue) -> list[tuple[float, str]]:
    """Stable-step limits of sub-models whose stiffness is not the Hertz one (coupler/dem/timestep.py adds them
    to the Rayleigh / Hertz limits): a Hooke normal spring, contact time / 10, pi sqrt(m*/k_n) / 10 with the
    smallest m* (m/2 of the lightest sphere of the pair's materials); a constant epsd2 rolling stiffness,
    rotational period / 10, 2 pi sqrt(I/k_r) / 10 with I = 2/5 m R^2 of that sphere."""
    out = []
    for (a, b), law in scene.contacts.items():
        kinds = [(r, m) for r, m in catalogue if m in (a, b)]
        if not kinds:
            continue
        masses = [(scene.materials[m].density * 4.0 / 3.0 * math.pi * r ** 3, r, m) for r, m in kinds]
        mass, r, mname = min(masses)
        if law.normal == "hooke":
            out.append((math.pi * math.sqrt(0.5 * mass / law.normal_stiffness) / 10.0,
                        f"Hooke contact time / 10, k_n={law.normal_stiffness:g} N/m, R={r:g} m ({mname})"))
        if law.rolling == "epsd2" and law.rolling_stiffness is not None:
            inertia = 0.4 * mass * r * r
            out.append((2.0 * math.pi * math.sqrt(inertia / law.rolling_stiffness) / 10.0,
                        f"rolling spring period / 10, k_r={law.rolling_stiffness:g} N m/rad, R={r:g} m ({mname})"))
    return out
