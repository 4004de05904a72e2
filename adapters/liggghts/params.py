"""Parameter map native scene -> LIGGGHTS 3.8 (one place; numbers of the pitfalls refer to shared/notes/dem_codes.md).

| native definition (coupler/dem/contact.py)         | LIGGGHTS 3.8                                                        |
|----------------------------------------------------|---------------------------------------------------------------------|
| E*, G*, S_n = 2E*sqrt(R* d), S_t = 8G*sqrt(R* d)   | same (`model hertz`, `tangential history`) from youngsModulus,     |
|                                                    | poissonsRatio per atom type                                         |
| gamma = 2 beta sqrt(S m*), beta per damping mode   | gamma = 2 sqrt(5/6) |ln e'|/sqrt(ln^2 e' + pi^2) sqrt(S m*): we pass  |
|                                                    | the e' whose LIGGGHTS beta equals the native beta (P1):             |
|                                                    | "liggghts": e' = e; "restitution": e' = e of beta_restitution(e)    |
|                                                    | (0.8 -> 0.79117); "yade": e' of beta_yade(e) (Thornton 2013)          |
| F_n >= 0 (never attractive)                        | `limitForce on` in pair_style and every wall/gran (P2)              |
| wall R* = R, m* = m                                | primitive and mesh walls use R* = R, m* = m (P3)                    |
| Coulomb cap on the elastic part, dashpot only while| same (P9, P17)                                                      |
| sticking; tangential spring total (secant) form    | same secant form (P8: YADE differs)                                 |
| friction per material pair                         | coefficientFriction peratomtypepair (P10)                           |
| SI units, E > 1e9 Pa                               | `hard_particles yes` (P14)                                          |
| tangential contact force                           | from `pair/gran/local force`, zeroed where the normal part is       |
|                                                    | clamped (the compute reports a stale tangential force there, P11)   |
| orientation                                        | spheres: LIGGGHTS does not integrate orientation -> q = NaN         |
| planar (2D) scenes                                 | `fix planeforce 0 0 1` keeps spheres in the x-y plane                |
| output times                                       | dumps every round(output_interval/dt) steps; the first contact      |
|                                                    | sample may be one interval later than native (P15)                  |
Not expressible here (UnsupportedFeature, never approximated): clusters with cluster_damping_mass = "sphere"
(LIGGGHTS multisphere always damps with the body mass, P5); rigid clusters and mesh walls are not yet written in
this adapter; planes whose normal is not along x, y or z; moving planes.
"""
from __future__ import annotations

import math

from coupler.dem.contact import beta_restitution, beta_yade
from coupler.scene import ContactLaw


def restitution_for_beta(beta: float) -> float:
    """Invert beta = sqrt(5/6) |ln e| / sqrt(ln^2 e + pi^2): ln e = -pi b / sqrt(1 - b^2), b = beta / sqrt(5/6)."""
    if beta <= 0.0:
        return 1.0
    b = beta / math.sqrt(5.0 / 6.0)
    if b >= 1.0:
        raise ValueError(f"damping ratio {beta} is beyond what a LIGGGHTS restitution can express")
    return math.exp(-math.pi * b / math.sqrt(1.0 - b * b))


def liggghts_restitution(law: ContactLaw) -> float:
    """The coefficientRestitution to give LIGGGHTS so that its damping equals the native law's (P1/P2)."""
    if law.damping == "liggghts":
        return law.restitution
    if law.damping == "restitution":
        return restitution_for_beta(beta_restitution(law.restitution))
    if law.damping == "yade":
        return restitution_for_beta(beta_yade(law.restitution))
    raise ValueError(law.damping)
