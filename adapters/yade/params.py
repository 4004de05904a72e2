"""Parameter map native scene -> YADE 2023.02a (pitfall numbers refer to shared/notes/dem_codes.md).

| native definition (coupler/dem/contact.py)          | YADE 2023.02a                                                      |
|-----------------------------------------------------|--------------------------------------------------------------------|
| E*, G*, Hertz S_n, Mindlin S_t                      | FrictMat(young, poisson) + Ip2_FrictMat_FrictMat_MindlinPhys:       |
|                                                     | kno = 4/3 E* sqrt(R*), k_n = 3/2 kno sqrt(d) = S_n; kso = 8 G* sqrt(R*) |
| gamma = 2 beta sqrt(S m*)                           | c_n = 2 betan sqrt(mbar k_n): we pass betan = betas = native beta    |
|                                                     | of the scene's damping mode (P1), never `en=` (Thornton 2013 map)  |
| F_n >= 0                                            | built into Law2_ScGeom_MindlinPhys_Mindlin (P2)                     |
| wall R* = R                                         | Ig2_Wall_Sphere_ScGeom(hertzian=True), Ig2_Facet_Sphere_ScGeom(hertzian=True) (P3) |
| one contact per flat wall                           | axis-aligned planes as utils.wall, never facets (facet edges double count, P4) |
| cluster damping mass                                | YADE clumps use the member mass ("sphere"); for "body" betan is scaled by sqrt(M/m_member) (P5) |
| cluster mass, inertia                               | appendClumped sums the member spheres: same as native "exact" (others: UnsupportedFeature) |
| planar clusters                                     | clump blockedDOFs = 'z' only: blocking rotations uses the wrong inertia (P6) |
| cluster orientation                                 | clump `ori` is its principal frame: reported relative to t = 0 (P12) |
| planar (2D) spheres                                 | blockedDOFs = 'zXY' (rotation blocking is safe for single spheres, not clumps: P6) |
| tangential spring                                   | YADE is incremental (tangent), native/LIGGGHTS total (secant): differs in partial slip only (P8, not mappable) |
| friction per pair                                   | YADE uses min(frictionAngle) of the two materials (P10): we require one friction for all pairs |
| force sign / id order                               | phys.normalForce + shearForce acts on id2; we take the sign from the id order (P13) |
| orientation                                         | Quaternion indexes q[0..2] = x, y, z and q[3] = w (P12); reported as (w, x, y, z) |
Not expressible (UnsupportedFeature): different friction or damping per material pair; moving walls; planes not
normal to x, y or z; meshes (not yet written in this adapter).
"""
from __future__ import annotations

import numpy as np

from coupler.dem.contact import damping_ratio
from coupler.errors import UnsupportedFeature
from coupler.scene import Scene


def yade_contact(scene: Scene) -> tuple[float, float]:
    """(betan = betas, friction coefficient) shared by all pairs (YADE has one Ip2 functor per scene)."""
    laws = list(scene.contacts.values())
    betas = {round(damping_ratio(l), 14) for l in laws}
    mus = {l.friction for l in laws}
    if len(betas) > 1:
        raise UnsupportedFeature("yade", "contacts", "different damping per material pair needs one MatchMaker per pair")
    if len(mus) > 1:
        raise UnsupportedFeature("yade", "contacts", "YADE takes min(frictionAngle) of two materials (notes P10); "
                                                     "give every pair the same friction")
    return float(betas.pop()), float(mus.pop())


def clump_beta_scale(scene: Scene) -> float:
    """Factor on betan so that YADE clump contacts (damped with the member mass) behave like the native "body"
    convention (damped with the cluster mass): sqrt(M / m_member) (P5). YADE has one betan per scene, so this needs
    equal members, one ratio M/m for all clusters, and no free spheres beside them."""
    dem = scene.dem
    if not dem.clusters or dem.cluster_damping_mass == "sphere":
        return 1.0
    ratios = set()
    for c in dem.clusters:
        t = dem.templates[c.template]
        if len(set(t.radii)) > 1:
            raise UnsupportedFeature("yade", "dem.cluster_damping_mass",
                                     "'body' needs betan x sqrt(M/m_member) (P5): members must be equal spheres")
        ratios.add(len(t.radii))
    if len(ratios) > 1 or dem.n_spheres:
        raise UnsupportedFeature("yade", "dem.cluster_damping_mass",
                                 "'body' needs one betan x sqrt(M/m_member) for the whole scene (P5): all clusters "
                                 "must have the same member count and there may be no free spheres")
    return float(np.sqrt(ratios.pop()))


def check_supported(scene: Scene) -> None:
    dem = scene.dem
    if dem is None or scene.mpm is not None:
        raise UnsupportedFeature("yade", "mpm", "YADE runs DEM-only scenes here")
    for k, c in enumerate(dem.clusters):
        t = dem.templates[c.template]
        if t.mass_properties != "exact":
            raise UnsupportedFeature("yade", f"dem.templates.{c.template}.mass_properties",
                                     "YADE clumps compute their own mass properties from the members ('exact' only)")
    clump_beta_scale(scene)
    if dem.meshes:
        raise UnsupportedFeature("yade", "dem.meshes", "facet export is not written yet in this adapter")
    for k, p in enumerate(dem.planes):
        if np.count_nonzero(p.normal) != 1:
            raise UnsupportedFeature("yade", f"dem.planes[{k}].normal", "only planes normal to x, y or z map to walls")
        if np.any(p.velocity != 0.0):
            raise UnsupportedFeature("yade", f"dem.planes[{k}].velocity", "moving walls")
    yade_contact(scene)
