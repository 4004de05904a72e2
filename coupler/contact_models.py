"""Registry of contact sub-models: one row per model, and the parser of their `[[contacts]]` fields.

Physical parameters only (no solver code), so the scene layer can parse contact laws; the kernels of each family
live in coupler/dem/contact/<family>.py and dispatch on the `code` given here.

Scene syntax (each field optional; the defaults give today's Hertz-Mindlin law)::

    [[contacts]]
    materials = ["steel", "steel"]
    restitution = 0.8
    friction = 0.3
    damping = "restitution"                   # "restitution" | "liggghts" | "yade"   (damping.py)
    normal = "hertz"                          # or { model = "hooke", stiffness = 1e5, tangential_ratio = 0.2857 }
    tangential = "history"                    # "history" | "no_history" | "incremental"
    rolling = { model = "cdt", coefficient = 0.05 }     # "none" (default) | cdt | epsd2 (+ stiffness)

To add a sub-model: write its kernel in the family's module (coupler/dem/contact/), add its row here (name,
code, parameters) and its branch in the family's dispatch function.
"""
from __future__ import annotations

from dataclasses import dataclass

from coupler.errors import SceneError


@dataclass(frozen=True)
class SubModel:
    family: str
    name: str
    code: int                  # id in the law table (coupler/dem/contact/law.py)
    params: tuple[str, ...]    # scene parameters of its table form
    doc: str


NORMAL = {m.name: m for m in (
    SubModel("normal", "hertz", 0, (), "Hertz: F = 4/3 E* sqrt(R*) d^1.5, S_t = 8 G* sqrt(R* d)"),
    SubModel("normal", "hooke", 1, ("stiffness", "tangential_ratio"),
             "linear spring: F = k_n d, S_t = tangential_ratio k_n (default 2/7)"),
)}
TANGENTIAL = {m.name: m for m in (
    SubModel("tangential", "history", 1, (), "Mindlin spring with history, Coulomb cap, dashpot while sticking"),
    SubModel("tangential", "no_history", 0, (), "capped tangential dashpot"),
    SubModel("tangential", "incremental", 2, (),
             "incremental (tangent) Mindlin spring dF = -S_t v_t dt, Coulomb cap, dashpot while sticking (YADE, Kratos)"),
)}
ROLLING = {m.name: m for m in (
    SubModel("rolling", "none", 0, (), "no rolling resistance"),
    SubModel("rolling", "cdt", 1, ("coefficient",), "constant directional torque mu_r R* F_n (LIGGGHTS cdt)"),
    SubModel("rolling", "epsd2", 2, ("coefficient", "stiffness"),
             "elastic-plastic spring k_r = S_t R*^2 (or constant), cap mu_r R* F_n (LIGGGHTS epsd2, YADE Mindlin)"),
)}
FAMILIES = {"normal": NORMAL, "tangential": TANGENTIAL, "rolling": ROLLING}
HOOKE_TANGENTIAL_RATIO = 2.0 / 7.0
# damping modes (coupler/dem/contact/damping.py) each normal model has a restitution -> beta map for
DAMPING_FOR_NORMAL = {"hertz": ("restitution", "liggghts", "yade"), "hooke": ("restitution", "liggghts")}


def _model(ct, field: str, registry: dict, default: str):
    """A sub-model field given as a name or as a table with `model` and parameters: (name, Table | None)."""
    raw = ct.raw_value(field, default)
    if isinstance(raw, str):
        name, tab = raw, None
    elif isinstance(raw, dict):
        tab = ct.table(field)
        name = tab.string("model")
    else:
        raise SceneError(ct.sub(field), f"must be a model name or a table {{ model = ... }}, got {raw!r}")
    if name not in registry:
        path = ct.sub(field) + (".model" if tab is not None else "")
        raise SceneError(path, f"must be one of {', '.join(map(repr, registry))}; got {name!r}")
    return name, tab


def parse_submodels(ct, damping: str) -> dict:
    """Read the sub-model fields of one `[[contacts]]` table; returns the ContactLaw keyword arguments."""
    out: dict = {}
    normal, nt = _model(ct, "normal", NORMAL, "hertz")
    out["normal"] = normal
    if normal == "hooke":
        if nt is None:
            raise SceneError(ct.sub("normal"), "hooke needs its stiffness: normal = { model = \"hooke\", "
                                               "stiffness = k_n [N/m] }")
        out["normal_stiffness"] = nt.number("stiffness", gt=0.0)
        out["tangential_ratio"] = nt.number("tangential_ratio", HOOKE_TANGENTIAL_RATIO, gt=0.0)
    if nt is not None:
        nt.done()
    if damping not in DAMPING_FOR_NORMAL[normal]:
        raise SceneError(ct.sub("damping"), f"must be one of {', '.join(map(repr, DAMPING_FOR_NORMAL[normal]))} "
                                            f"with normal {normal!r}; got {damping!r}")
    tang = ct.string("tangential", "history", choices=tuple(TANGENTIAL))
    out["tangential"] = tang
    rolling, rt = _model(ct, "rolling", ROLLING, "none")
    out["rolling"] = rolling
    if rolling != "none":
        if rt is None:
            raise SceneError(ct.sub("rolling"), f"{rolling} needs its coefficient: rolling = {{ model = "
                                                f"\"{rolling}\", coefficient = mu_r }}")
        out["rolling_coefficient"] = rt.number("coefficient", ge=0.0)
        if rolling == "epsd2":
            k = rt.raw_value("stiffness", "tangential")
            if isinstance(k, str):
                if k != "tangential":
                    raise SceneError(rt.sub("stiffness"), f"must be \"tangential\" (k_r = S_t R*^2) or a number "
                                                          f"> 0 [N m/rad]; got {k!r}")
                out["rolling_stiffness"] = None
            else:
                from coupler.fields import check_number
                out["rolling_stiffness"] = check_number(rt.sub("stiffness"), k, gt=0.0)
    if rt is not None:
        rt.done()
    return out
