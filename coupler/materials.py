"""Physical parameters shared by all solvers: materials (`[materials.<name>]`) and contact laws (`[[contacts]]`).

No solver code lives here and nothing here imports a solver: the DEM (coupler/dem/), the MPM (coupler/mpm/) and
the reference-code adapters (adapters/) read these records and map them to their own definitions, each in one
place (DEM: coupler/dem/contact/; LIGGGHTS: adapters/liggghts/params.py; YADE: adapters/yade/params.py).

    [materials.aluminium]
    density = 2700.0              # kg/m^3, > 0
    young = 70e9                  # Pa, > 0
    poisson = 0.33                # (-1, 0.5)

    [[contacts]]                  # one per material pair that can touch
    materials = ["aluminium", "aluminium"]
    restitution = 0.8             # (0, 1]
    friction = 0.3                # >= 0
    tangential = "history"        # history | no_history | incremental (coupler/dem/contact/tangential.py)
    damping = "restitution"       # restitution | liggghts | yade (see ContactLaw)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from coupler.errors import SceneError
from coupler.contact_models import parse_submodels
from coupler.fields import Table

DAMPING_MODES = ("restitution", "liggghts", "yade")


@dataclass(frozen=True)
class Material:
    name: str
    density: float
    young: float
    poisson: float

    @property
    def shear_modulus(self) -> float:
        return self.young / (2.0 * (1.0 + self.poisson))


@dataclass(frozen=True)
class ContactLaw:
    """Contact law of a material pair, composed of sub-models (formulas and definitions in coupler/dem/contact/).

    damping: how `restitution` becomes the damping ratio beta:
      * "restitution" (default): beta chosen so that a binary impact with the F_n >= 0 clamp delivers exactly
        the asked restitution (inverse of the clamped Hertz ODE, coupler/dem/contact/damping.py).
      * "liggghts": beta = ln e / sqrt(ln^2 e + pi^2), gamma = 2 sqrt(5/6) |beta| sqrt(S_n m*) (LIGGGHTS 3.8).
      * "yade": YADE `en=` mapping (Thornton et al. 2013), c_n = 2 beta_n sqrt(m* k_n).
    """
    materials: tuple[str, str]
    restitution: float
    friction: float
    tangential: str = "history"     # "history" | "no_history" | "incremental" (coupler/dem/contact/tangential.py)
    damping: str = "restitution"
    # sub-models (coupler/dem/contact/registry.py): normal "hertz" | "hooke" (+ k_n, k_t/k_n), rolling
    # "none" | "cdt" | "epsd2" (+ mu_r; epsd2 stiffness None = S_t R*^2, else a constant k_r [N m/rad])
    normal: str = "hertz"
    normal_stiffness: float = 0.0
    tangential_ratio: float = 0.0
    rolling: str = "none"
    rolling_coefficient: float = 0.0
    rolling_stiffness: float | None = None


def pair_key(a: str, b: str) -> tuple[str, str]:
    """The key of a material pair in `Scene.contacts` (order-independent)."""
    return (a, b) if a <= b else (b, a)


def rayleigh_time(mat: Material, radius: float) -> float:
    """Rayleigh wave time step pi R sqrt(rho/G) / (0.1631 nu + 0.8766) (Li et al. 2005)."""
    return math.pi * radius * math.sqrt(mat.density / mat.shear_modulus) / (0.1631 * mat.poisson + 0.8766)


def parse_materials(t: Table) -> dict[str, Material]:
    """The `[materials.<name>]` tables of the scene's top-level table `t`."""
    materials: dict[str, Material] = {}
    for mname, mt in t.named_tables("materials").items():
        materials[mname] = Material(
            name=mname,
            density=mt.number("density", gt=0.0),
            young=mt.number("young", gt=0.0),
            poisson=mt.number("poisson", gt=-1.0, lt=0.5),
        )
        mt.done()
    return materials


def parse_contacts(t: Table, materials: dict[str, Material]) -> dict[tuple[str, str], ContactLaw]:
    """The `[[contacts]]` array of the scene's top-level table `t`, keyed by `pair_key`."""
    contacts: dict[tuple[str, str], ContactLaw] = {}
    for ct in t.tables("contacts"):
        mats = ct.raw_value("materials")
        if (not isinstance(mats, list) or len(mats) != 2 or not all(isinstance(m, str) for m in mats)):
            raise SceneError(ct.sub("materials"), f"must be a list of two material names, got {mats!r}")
        for i, m in enumerate(mats):
            if m not in materials:
                raise SceneError(f"{ct.sub('materials')}[{i}]",
                                 f"unknown material {m!r} (defined: {', '.join(sorted(materials)) or 'none'})")
        key = pair_key(*mats)
        if key in contacts:
            raise SceneError(ct.sub("materials"), f"a contact law for {key} is already defined")
        damping = ct.string("damping", "restitution", choices=DAMPING_MODES)
        contacts[key] = ContactLaw(
            materials=key,
            restitution=ct.number("restitution", gt=0.0, le=1.0),
            friction=ct.number("friction", ge=0.0),
            damping=damping,
            **parse_submodels(ct, damping),
        )
        ct.done()
    return contacts
