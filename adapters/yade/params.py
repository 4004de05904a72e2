"""Parameter map native scene -> YADE 2023.02a (pitfall numbers refer to shared/notes/dem_codes.md).

| native definition (coupler/dem/contact.py)          | YADE 2023.02a                                                      |
|-----------------------------------------------------|--------------------------------------------------------------------|
| E*, G*, Hertz S_n, Mindlin S_t                      | FrictMat(young, poisson) + Ip2_FrictMat_FrictMat_MindlinPhys:       |
|                                                     | kno = 4/3 E* sqrt(R*), k_n = 3/2 kno sqrt(d) = S_n; kso = 8 G* sqrt(R*) |
| gamma = 2 beta sqrt(S m*)                           | c_n = 2 betan sqrt(mbar k_n): betan = betas = native beta of the     |
|                                                     | scene's damping mode (P1), never `en=`; one MatchMaker value per   |
|                                                     | material pair (damping per pair, P5 mass scaling: beta_pairs)       |
| F_n >= 0                                            | built into Law2_ScGeom_MindlinPhys_Mindlin (P2)                     |
| wall R* = R                                         | Ig2_Wall_Sphere_ScGeom(hertzian=True), Ig2_Facet_Sphere_ScGeom(hertzian=True) (P3) |
| rigid wall (E*, G* from the sphere alone)           | a FrictMat `<material>@rigid` with young 1e12 x the largest modulus, |
|                                                     | same poisson, density and betan (E* relative error < 2e-12)         |
| one contact per flat wall                           | axis-aligned planes as utils.wall, never facets (facet edges double count, P4) |
| mesh walls (face/edge/vertex hierarchy)             | one utils.facet per triangle (2D segments: strips along z); YADE makes one contact per |
|                                                     | facet, so near shared edges/vertices a sphere is pushed twice (P4): after the          |
|                                                     | InteractionLoop a PyRunner applies the native hierarchy per sphere and mesh and takes  |
|                                                     | the dominated contacts' force and torque back (count in summary.json)                  |
| moving planes / meshes (constant velocity)          | Wall / facet bodies are non-dynamic: state.vel is kept and NewtonIntegrator moves them;|
|                                                     | the contact uses that velocity (ScGeom incident velocity)                              |
| cluster damping mass                                | YADE clumps use the member mass ("sphere"); for "body" betan of the pair is scaled by sqrt(m*_native/m*_YADE) (P5) |
| cluster mass, inertia                               | appendClumped sums the member spheres: same as native "exact" (others: UnsupportedFeature) |
| planar clusters                                     | clump blockedDOFs = 'z' only: blocking rotations uses the wrong inertia (P6) |
|                                                     | (writer.py). The coupled partition blocks 'zXY' and sets state.inertia to the |
|                                                     | global diagonal, which the spherical rotation path uses per global component: |
|                                                     | free X, Y let loaded sliding clumps tilt out of plane (partition_server.py) |
| prescribed cluster motion (fixed / velocity, until) | clump blockedDOFs = 'xyzXYZ' + vel, angVel until the native release step, then 'z' / '' and angMom from angVel (writer.py) |
| cluster orientation                                 | clump `ori` is its principal frame: reported relative to t = 0 (P12) |
| planar (2D) spheres                                 | blockedDOFs = 'zXY' (rotation blocking is safe for single spheres, not clumps: P6) |
| tangential "history" (total spring)                 | YADE is incremental (tangent), native/LIGGGHTS total (secant): differs in partial slip only (P8, not mappable) |
| tangential "incremental"                            | the same law: Mindlin's shearElastic = rotate(F) - k_s v_s dt (native projects the old force on the new tangent plane: the same to first order in the normal's turn; no twist term, which is 0 for planar motion) |
| friction per pair                                   | YADE uses min(frictionAngle) of the two materials (P10): we require one friction for all pairs |
| force sign / id order                               | phys.normalForce + shearForce acts on id2; we take the sign from the id order (P13) |
| orientation                                         | Quaternion indexes q[0..2] = x, y, z and q[3] = w (P12); reported as (w, x, y, z) |
| normal "hertz" / tangential "history", "incremental" | Mindlin (a Hooke normal or "no_history": UnsupportedFeature)      |
| rolling "none"                                      | Law2_ScGeom_MindlinPhys_Mindlin(includeMoment=False)              |
| rolling "epsd2", mu_r, constant stiffness k_r       | includeMoment=True, Ip2 krot = k_r, ktwist = 0 and eta with        |
|                                                     | maxBendPl = eta Rmean = mu_r R*: the moment is an incremental     |
|                                                     | spring -k_r w_t dt capped at maxBendPl |F_n| (F_n after damping,   |
|                                                     | HertzMindlin.cpp), as native epsd2. Rmean = (refR1 + refR2)/2:    |
|                                                     | for sphere-wall (hertzian=True, refR1 = 1e8 R) R*/Rmean =          |
|                                                     | 2e8/(1e8+1)^2, for two spheres of one radius 1/2; eta and krot are |
|                                                     | one number per run, so scenes with both kinds, several radii or    |
|                                                     | several (mu_r, k_r) are UnsupportedFeature                         |
| rolling "epsd2", stiffness "tangential"             | UnsupportedFeature: YADE's krot is a constant, k_r = S_t R*^2 varies |
|                                                     | with the overlap                                                   |
| rolling "cdt"                                       | UnsupportedFeature: YADE has no constant-directional-torque law    |
Not expressible (UnsupportedFeature): different friction per material pair; a material pair whose bodies need
different P5 damping-mass scales (bodies of different mass sharing a material); planes not normal to x, y or z
(YADE Wall bodies are axis-aligned); a time-dependent gravity.
"""
from __future__ import annotations

import numpy as np

from coupler.dem.contact import damping_ratio
from adapters.common import prescribed_motions
from coupler.errors import UnsupportedFeature
from coupler.scene import Scene


def yade_contact(scene: Scene) -> float:
    """The friction coefficient shared by all pairs (damping per pair: beta_pairs)."""
    mus = {l.friction for l in scene.contacts.values()}
    if not mus:
        return 0.0                      # no pair can touch (e.g. one sphere alone): no friction to give
    if len(mus) > 1:
        raise UnsupportedFeature("yade", "contacts", "YADE takes min(frictionAngle) of two materials (notes P10); "
                                                     "give every pair the same friction")
    return float(mus.pop())


def _mass_kinds(scene: Scene) -> dict[str, set]:
    """Per material, the distinct (native damping mass, YADE damping mass) of the bodies made of it [kg];
    inf for walls. Native "body" convention: a cluster member is damped with the cluster mass M, YADE always with
    the member mass m (P5)."""
    dem = scene.dem
    kinds: dict[str, set] = {m: set() for m in scene.materials}
    for r, mat in zip(dem.radius, dem.material):
        m = scene.materials[mat].density * 4.0 / 3.0 * np.pi * r ** 3
        kinds[mat].add((round(m, 18), round(m, 18)))
    for c in dem.clusters:
        t = dem.templates[c.template]
        ms = scene.materials[c.material].density * 4.0 / 3.0 * np.pi * t.radii ** 3
        M = float(ms.sum())
        for m in ms:
            kinds[c.material].add((round(M if dem.cluster_damping_mass == "body" else m, 18), round(m, 18)))
    for p in list(dem.planes) + list(dem.meshes):
        kinds[p.material].add((np.inf, np.inf))
    return kinds


def _reduced(a: float, b: float) -> float:
    return 1.0 / ((1.0 / a if np.isfinite(a) else 0.0) + (1.0 / b if np.isfinite(b) else 0.0))


def beta_pairs(scene: Scene) -> dict[tuple[str, str], float]:
    """betan (= betas) per material pair for a YADE MatchMaker (P5). YADE damps with c = 2 betan sqrt(mbar k) and
    mbar from the member masses; the native law with m* from the scene's convention, so
    betan = beta sqrt(m*_native / m*_YADE). This must be one number per material pair: every pair of body kinds
    (free sphere of a given mass, member of a given cluster mass, wall) of the two materials must give the same
    ratio, else UnsupportedFeature names the pair (give such bodies their own material)."""
    kinds = _mass_kinds(scene)
    out = {}
    for (a, b), law in scene.contacts.items():
        ratios = set()
        for na, ya in kinds.get(a, ()):
            for nb, yb in kinds.get(b, ()):
                if not (np.isfinite(na) or np.isfinite(nb)):
                    continue                                  # wall - wall
                ratios.add(round(_reduced(na, nb) / _reduced(ya, yb), 12))
        if len(ratios) > 1:
            raise UnsupportedFeature("yade", f"contacts[{a}, {b}]",
                                     f"one betan per material pair (MatchMaker) cannot express the native damping "
                                     f"masses here: m*_native / m*_YADE takes the values {sorted(ratios)} (P5); "
                                     f"give bodies of different cluster/sphere mass different materials")
        scale = float(np.sqrt(ratios.pop())) if ratios else 1.0
        out[(a, b)] = float(damping_ratio(law)) * scale
    return out


def check_supported(scene: Scene) -> None:
    dem = scene.dem
    if dem is None or scene.mpm is not None:
        raise UnsupportedFeature("yade", "mpm", "YADE runs DEM-only scenes here")
    if scene.gravity_schedule is not None:
        raise UnsupportedFeature("yade", "gravity_schedule", "a time-dependent gravity is not written in this adapter")
    from coupler.dem.timestep import chosen_dt
    dt = chosen_dt(scene)
    prescribed_motions("yade", scene, dt, int(round(scene.time.t_end / dt)))      # the writer's checks
    for k, c in enumerate(dem.clusters):
        t = dem.templates[c.template]
        if t.mass_properties != "exact":
            raise UnsupportedFeature("yade", f"dem.templates.{c.template}.mass_properties",
                                     "YADE clumps compute their own mass properties from the members ('exact' only)")
    beta_pairs(scene)
    yade_rolling(scene)
    for k, p in enumerate(dem.planes):
        if np.count_nonzero(p.normal) != 1:
            raise UnsupportedFeature("yade", f"dem.planes[{k}].normal", "only planes normal to x, y or z map to "
                                                                         "YADE Wall bodies")
    yade_contact(scene)


# rigid walls (`rigid = true`): the wall gets a FrictMat `<material>@rigid` of its own with young = RIGID_FACTOR x the
# largest modulus (Ip2_FrictMat_FrictMat_MindlinPhys: E* = Ea Eb / ((1 - nu_a^2) Eb + (1 - nu_b^2) Ea) then differs from
# E_s / (1 - nu_s^2) by < 2e-12 relative, the same for G*) and the same betan as its material (MatchMaker row copied)
RIGID_FACTOR = 1e12
RIGID_SUFFIX = "@rigid"


def wall_material(w) -> str:
    """The YADE material name of a plane or mesh wall: its material, or `<material>@rigid` for a rigid wall."""
    return w.material + RIGID_SUFFIX if getattr(w, "rigid", False) else w.material


def rigid_materials(scene: Scene) -> dict[str, dict]:
    """FrictMat properties of the rigid wall materials (name -> young, poisson, density)."""
    e_max = max(m.young for m in scene.materials.values())
    out = {}
    for w in list(scene.dem.planes) + list(scene.dem.meshes):
        if getattr(w, "rigid", False):
            m = scene.materials[w.material]
            out[wall_material(w)] = {"young": RIGID_FACTOR * e_max, "poisson": m.poisson, "density": m.density}
    return out


def beta_matches(scene: Scene, pairs: dict[tuple[str, str], float]) -> list[list]:
    """MatchMaker rows [a, b, betan]: beta_pairs, plus each pair's row for the rigid copy of a wall material."""
    rows = [[a, b, v] for (a, b), v in pairs.items()]
    for rname in rigid_materials(scene):
        base = rname[:-len(RIGID_SUFFIX)]
        for (a, b), v in pairs.items():
            if base in (a, b):
                other = b if a == base else a
                rows.append([other, rname, v])
    return rows


WALL_RSTAR_OVER_RMEAN = 2e8 / (1e8 + 1.0) ** 2      # hertzian=True walls/facets: refR1 = 1e8 R (notes P3)


def yade_rolling(scene: Scene) -> dict | None:
    """Ip2 krot/eta and Law2 includeMoment for the scene's rolling model (None: no rolling resistance)."""
    laws = list(scene.contacts.values())
    for k, l in enumerate(laws):
        if l.normal != "hertz":
            raise UnsupportedFeature("yade", f"contacts[{k}].normal", f"normal {l.normal!r} is not mapped to YADE "
                                                                      "(Mindlin is Hertz)")
        if l.tangential == "no_history":
            raise UnsupportedFeature("yade", f"contacts[{k}].tangential", "YADE Mindlin always has a tangential "
                                                                          "spring ('no_history' not expressible)")
        if l.rolling == "cdt":
            raise UnsupportedFeature("yade", f"contacts[{k}].rolling", "YADE has no constant-directional-torque "
                                                                       "rolling law ('cdt')")
        if l.rolling == "epsd2" and l.rolling_stiffness is None:
            raise UnsupportedFeature("yade", f"contacts[{k}].rolling.stiffness",
                                     "YADE krot is a constant; k_r = S_t R*^2 ('tangential') varies with the "
                                     "overlap: give a constant stiffness [N m/rad]")
    rolling = {(l.rolling, l.rolling_coefficient, l.rolling_stiffness) for l in laws}
    if all(r[0] == "none" for r in rolling):
        return None
    if len(rolling) > 1:
        raise UnsupportedFeature("yade", "contacts", "YADE Ip2 krot and eta are one number per run: every contact "
                                                     f"needs the same rolling model, got {sorted(map(str, rolling))}")
    _, mur, kr = rolling.pop()
    dem = scene.dem
    walls = len(dem.planes) + len(dem.meshes) > 0
    spheres = dem.n_spheres + sum(len(dem.templates[c.template].radii) for c in dem.clusters)
    radii = set(np.round(dem.radius, 15).tolist())
    for c in dem.clusters:
        radii |= set(np.round(dem.templates[c.template].radii, 15).tolist())
    if walls and (spheres > 1):
        raise UnsupportedFeature("yade", "contacts.rolling", "YADE eta = mu_r R*/Rmean is one number: sphere-wall "
                                                             "and sphere-sphere contacts need different values")
    if not walls and len(radii) > 1:
        raise UnsupportedFeature("yade", "contacts.rolling", "YADE eta = mu_r R*/Rmean is one number: spheres of "
                                                             "different radii need different values")
    ratio = WALL_RSTAR_OVER_RMEAN if walls else 0.5
    return {"krot": float(kr), "eta": float(mur) * ratio, "mu_r": float(mur)}
