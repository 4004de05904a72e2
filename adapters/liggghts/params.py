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
| rigid wall (E*, G* from the sphere alone)          | the wall gets a type `<material>@rigid` with youngsModulus         |
|                                                    | 1e12 x the largest modulus (E* relative error < 2e-12; same law)    |
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
| rigid clusters                                     | `fix multisphere`; one `particletemplate/multisphere` per template  |
|                                                    | and material with `mass M inertia_tensor Ixx Ixy Ixz Iyy Iyz Izz    |
|                                                    | use_density` = the native exact values and the member offsets from  |
|                                                    | the exact COM (no Monte Carlo mass, COM or inertia, P7); each body   |
|                                                    | inserted by `fix insert/pack` in a 2e-15 m box at its COM with      |
|                                                    | `orientation constant` and its velocity, in a 1e-15 s step          |
| cluster damping mass                               | body mass only (P5): "body" maps, "sphere" is UnsupportedFeature    |
| planar clusters                                    | template `fflag on on off tflag off off on` (global-frame flags)    |
| prescribed cluster motion (fixed / velocity, until)| own template with `fflag off off off tflag off off off`, inserted    |
|                                                    | with the prescribed v, w; `run N` + `fix_modify ms fflag/tflag` (the |
|                                                    | free flags) + `run` at the native release step (writer.py)          |
| cluster orientation                                | `multisphere property quat` is relative to the template principal   |
|                                                    | frame: reported as the rotation since t = 0 applied to the scene   |
|                                                    | orientation (P12); kinetic energy from vcm, omega, angmom (P16)      |
| mesh walls                                         | ASCII STL + `fix mesh/surface` + `wall/gran ... mesh` with          |
|                                                    | `limitForce on` (P2; R* = R as primitive walls, P3); LIGGGHTS meets |
|                                                    | a shared edge once (P4 needs nothing here); 2D segments -> strips   |
|                                                    | along z; the simulation box holds every node for the whole run      |
|                                                    | (fix_mesh.cpp deletes elements outside it: checked in the log)      |
| moving meshes (constant velocity)                  | `fix move/mesh mesh <id> linear vx vy vz`                           |
| moving or tilted planes                            | primitive walls take a constant position (and `shear` along one     |
|                                                    | axis only): such planes become one STL triangle that contains the   |
|                                                    | plane's section of the region of the bodies (no inner edge), moved  |
|                                                    | by `move/mesh linear`; the parser checks no body left that region   |
| normal "hertz"                                     | `model hertz` (a Hooke normal: UnsupportedFeature, not written)     |
| tangential "history" / "no_history"                | `tangential history` / `tangential no_history`                       |
| tangential "incremental" (YADE's tangent spring)   | UnsupportedFeature: LIGGGHTS 3.8 has the total spring only (P8)      |
| rolling "none"                                     | no `rolling_friction` keyword                                        |
| rolling "cdt", mu_r                                | `rolling_friction cdt` + coefficientRollingFriction peratomtypepair |
|                                                    | = mu_r (LIGGGHTS uses the elastic k_n d of F_n and, on walls, the   |
|                                                    | arm R - d/2 instead of R*: equal in steady rolling up to d/(2R))    |
| rolling "epsd2", mu_r, stiffness "tangential"      | `rolling_friction epsd2` (k_r = k_t R*^2, cap mu_r R* F_n), same   |
|                                                    | coefficient; a constant k_r: UnsupportedFeature                     |
| one rolling model for all pairs                    | pair_style/wall/gran take one model: pairs that differ (model, not  |
|                                                    | coefficient) are UnsupportedFeature                                 |
| restitution range                                  | LIGGGHTS takes 0.05 < coefficientRestitution <= 1: a law whose     |
|                                                    | mapped e' is outside (restitution below ~0.21 with "restitution",  |
|                                                    | below 0.05 with "liggghts") is UnsupportedFeature naming the pair, |
|                                                    | e' and the range (check_restitution_range)                          |
Not expressible here (UnsupportedFeature, never approximated): clusters with cluster_damping_mass = "sphere"
(LIGGGHTS multisphere always damps with the body mass, P5); contact rows of cluster members; a time-dependent
gravity; MPM.
"""
from __future__ import annotations

import math

from coupler.dem.contact import beta_restitution, beta_yade
from coupler.errors import UnsupportedFeature
from coupler.materials import ContactLaw
from coupler.scene import Scene


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


# LIGGGHTS 3.8 global_properties: "0.05 < coefficientRestitution <= 1 required" (any other value stops the run)
RESTITUTION_RANGE = (0.05, 1.0)


def _mapped(law: ContactLaw, e: float) -> float:
    """liggghts_restitution of `law` with restitution e; 0 where no LIGGGHTS coefficient gives that damping."""
    try:
        return liggghts_restitution(ContactLaw(law.materials, e, law.friction, damping=law.damping,
                                               normal=law.normal))
    except ValueError:
        return 0.0


def lowest_restitution(law: ContactLaw) -> float:
    """The lowest `restitution` of this damping mode whose mapped coefficient LIGGGHTS accepts (bisection)."""
    lo, hi = 1e-6, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _mapped(law, mid) <= RESTITUTION_RANGE[0] else (lo, mid)
    return hi


def check_restitution_range(scene: Scene) -> None:
    """Every contact law's mapped coefficientRestitution inside LIGGGHTS' range, else UnsupportedFeature naming
    the pair, the mapped value and the range (the asked damping cannot be written with `model hertz`)."""
    for k, (key, law) in enumerate(scene.contacts.items()):
        e_l = _mapped(law, law.restitution)
        if not RESTITUTION_RANGE[0] < e_l <= RESTITUTION_RANGE[1]:
            value = f"{e_l:.4g}" if e_l > 0.0 else "none (the damping ratio exceeds any LIGGGHTS coefficient)"
            raise UnsupportedFeature(
                "liggghts", f"contacts[{k}].restitution",
                f"pair {key}: restitution {law.restitution:g} with damping = {law.damping!r} maps to LIGGGHTS "
                f"coefficientRestitution {value}; LIGGGHTS requires {RESTITUTION_RANGE[0]:g} < coefficientRestitution"
                f" <= 1 (lowest restitution this damping mode can map: {lowest_restitution(law):.3g})")


# rigid walls (`rigid = true`): a LIGGGHTS atom type of its own whose youngsModulus is RIGID_FACTOR x the largest
# modulus of the scene, so 1/E* = (1 - nu_s^2)/E_s + (1 - nu_w^2)/E_w differs from the sphere-alone value by at
# most (1 - nu_w^2)/(RIGID_FACTOR (1 - nu_s^2)) < 2e-12 relative (the same for G*); LIGGGHTS takes one modulus per type
RIGID_FACTOR = 1e12
RIGID_SUFFIX = "@rigid"


def wall_type(w) -> str:
    """The LIGGGHTS type name of a plane or mesh wall: its material, or `<material>@rigid` for a rigid wall."""
    return w.material + RIGID_SUFFIX if getattr(w, "rigid", False) else w.material


def type_names(scene: Scene) -> list[str]:
    """Atom type names in type order: the scene's materials, then one rigid type per rigid wall material."""
    dem = scene.dem
    rigid = sorted({wall_type(w) for w in list(dem.planes) + list(dem.meshes) if getattr(w, "rigid", False)})
    return sorted(scene.materials) + rigid


def real_material(name: str) -> str:
    """The scene material of a type name (the contact law of a rigid type is its material's)."""
    return name[:-len(RIGID_SUFFIX)] if name.endswith(RIGID_SUFFIX) else name


def type_young(scene: Scene, name: str) -> float:
    """youngsModulus of a type: the material's, or RIGID_FACTOR x the largest modulus for a rigid type."""
    if name.endswith(RIGID_SUFFIX):
        return RIGID_FACTOR * max(m.young for m in scene.materials.values())
    return scene.materials[name].young


def liggghts_model(scene: Scene) -> str:
    """The `model ... tangential ... [rolling_friction ...]` words of pair_style gran and every wall/gran.
    LIGGGHTS takes one model for all type pairs, so every contact law must use the same sub-models."""
    kinds = {(l.normal, l.tangential, l.rolling) for l in scene.contacts.values()}
    if len(kinds) > 1:
        raise UnsupportedFeature("liggghts", "contacts", f"LIGGGHTS takes one contact model for all type pairs; "
                                                         f"the scene mixes {sorted(kinds)}")
    normal, tangential, rolling = kinds.pop() if kinds else ("hertz", "history", "none")
    for k, l in enumerate(scene.contacts.values()):
        if l.normal != "hertz":
            raise UnsupportedFeature("liggghts", f"contacts[{k}].normal", f"normal {l.normal!r} is not mapped to "
                                                                          "LIGGGHTS (only 'hertz')")
        if l.tangential == "incremental":
            raise UnsupportedFeature("liggghts", f"contacts[{k}].tangential", "LIGGGHTS 3.8 has no incremental "
                                     "(tangent) spring: 'history' is its total spring (notes P8)")
        if l.rolling == "epsd2" and l.rolling_stiffness is not None:
            raise UnsupportedFeature("liggghts", f"contacts[{k}].rolling.stiffness",
                                     "LIGGGHTS epsd2 has k_r = k_t R*^2; a constant rolling stiffness cannot be "
                                     "expressed")
    words = f"model hertz tangential {tangential}"
    if rolling != "none":
        words += f" rolling_friction {rolling}"
    return words


def rolling_coefficient(law: ContactLaw) -> float:
    """coefficientRollingFriction of a pair: mu_r, the same definition (cap mu_r R* F_n)."""
    return law.rolling_coefficient
