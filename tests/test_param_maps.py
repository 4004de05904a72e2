"""Parameter maps to LIGGGHTS and YADE: every pitfall of shared/notes/dem_codes.md that applies to what the
adapters write (no binary needed)."""
import math

import pytest

from adapters.liggghts.params import liggghts_restitution, restitution_for_beta
from adapters.liggghts.writer import write_inputs as write_liggghts
from adapters.yade.params import yade_contact
from adapters.yade.writer import write_inputs as write_yade
from coupler.dem.contact import beta_liggghts, beta_restitution, beta_yade
from coupler.errors import UnsupportedFeature
from coupler.scene import ContactLaw, loads_scene
from tests.conftest import BASE_SCENE


@pytest.mark.parametrize("e", [0.1, 0.5, 0.8, 0.95])
def test_p1_liggghts_restitution_inverse(e):
    assert beta_liggghts(restitution_for_beta(beta_liggghts(e))) == pytest.approx(beta_liggghts(e), rel=1e-12)
    assert restitution_for_beta(beta_liggghts(e)) == pytest.approx(e, rel=1e-12)


def test_p1_p2_each_damping_mode_maps_to_the_same_beta():
    law = ContactLaw(("a", "a"), 0.8, 0.3)
    assert liggghts_restitution(law) == pytest.approx(0.79117, abs=1e-5)          # notes P2 [ODE]
    assert beta_liggghts(liggghts_restitution(law)) == pytest.approx(beta_restitution(0.8), rel=1e-12)
    yl = ContactLaw(("a", "a"), 0.8, 0.3, damping="yade")
    assert beta_liggghts(liggghts_restitution(yl)) == pytest.approx(beta_yade(0.8), rel=1e-12)
    ll = ContactLaw(("a", "a"), 0.8, 0.3, damping="liggghts")
    assert liggghts_restitution(ll) == 0.8


def test_p1_yade_gets_betan_not_en():
    from adapters.yade.params import beta_pairs
    scene = loads_scene(BASE_SCENE)
    assert yade_contact(scene) == 0.3
    assert beta_pairs(scene) == {("aluminium", "aluminium"): pytest.approx(beta_restitution(0.8), rel=1e-14)}


def test_liggghts_script_limitforce_hard_particles_and_walls(tmp_path):
    write_liggghts(loads_scene(BASE_SCENE), tmp_path)
    s = (tmp_path / "in.liggghts").read_text()
    assert "hard_particles yes" in s                                                   # P14
    assert s.count("limitForce on") == 2                                               # P2: pair + wall
    assert "primitive type 1 yplane 0 store_force yes limitForce on" in s              # P3: R* = R
    assert "coefficientRestitution peratomtypepair 1 0.79117" in s


def test_yade_script_hertzian_walls_no_facets_and_quaternion_order(tmp_path):
    write_yade(loads_scene(BASE_SCENE), tmp_path)
    s = (tmp_path / "run_yade.py").read_text()
    assert "Ig2_Wall_Sphere_ScGeom(hertzian=True)" in s                               # P3
    assert "utils.facet" not in s and "utils.wall" in s                                # P4
    assert "q[3], q[0], q[1], q[2]" in s                                               # P12: (w, x, y, z)
    assert "normalForce + I.phys.shearForce" in s and "f = -f2" in s                   # P13: sign by id order


def test_yade_planar_blocks_rotations_only_for_spheres(tmp_path):
    write_yade(loads_scene(BASE_SCENE.replace("dimension = 3", "dimension = 2")), tmp_path)
    assert 'blockedDOFs = "zXY"' in (tmp_path / "run_yade.py").read_text()             # P6 applies to clumps


def test_p10_yade_rejects_pair_dependent_friction():
    text = BASE_SCENE.replace("[[contacts]]", """[materials.steel]
density = 7800.0
young = 200e9
poisson = 0.3
[[contacts]]
materials = ["steel", "aluminium"]
restitution = 0.8
friction = 0.5
[[contacts]]
materials = ["steel", "steel"]
restitution = 0.8
friction = 0.3
[[contacts]]""")
    with pytest.raises(UnsupportedFeature, match="min\\(frictionAngle\\)"):
        yade_contact(loads_scene(text))


def test_p5_liggghts_cannot_damp_clusters_with_sphere_mass():
    from adapters.liggghts.writer import check_supported
    text = BASE_SCENE.replace("[dem]", """[dem]
cluster_damping_mass = "sphere"
[dem.templates.blk]
grid = {nx = 2, ny = 2, radius = 2.5e-3}
[[dem.clusters]]
template = "blk"
material = "aluminium"
position = [0.1, 0.1, 0.0]""")
    with pytest.raises(UnsupportedFeature, match="P5"):
        check_supported(loads_scene(text))


def test_unsupported_geometry_is_named():
    from adapters.liggghts.writer import check_supported
    text = BASE_SCENE.replace("normal = [0.0, 1.0, 0.0]", "normal = [0.0, 1.0, 1.0]").replace(
        "point = [0.0, 0.0, 0.0]", "point = [0.0, -1.0, 0.0]")
    with pytest.raises(UnsupportedFeature, match=r"dem.planes\[0\].normal: not supported by backend 'liggghts'"):
        check_supported(loads_scene(text))


def test_p11_clamped_tail_tangential_force_is_zeroed(tmp_path):
    """pair/gran/local keeps a stale tangential force where F_n is clamped; the parser must report 0 there."""
    import numpy as np
    from adapters.liggghts.parser import parse
    text = BASE_SCENE + """
[[dem.spheres]]
name = "b"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0076, 0.0]
"""
    scene = loads_scene(text)
    (tmp_path / "atoms.dump").write_text(
        "ITEM: TIMESTEP\n10\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS\n0 1\n0 1\n0 1\n"
        "ITEM: ATOMS id x y z vx vy vz omegax omegay omegaz f_force_w0[1] f_force_w0[2] f_force_w0[3]\n"
        "1 0 0.0026 0 0 0 0 0 0 0 0 0 0\n2 0 0.00759 0 0 0 0 0 0 0 0 0 0\n")
    # force on atom 1 pointing towards atom 2 (attractive normal part): clamped by limitForce, tangential stale
    (tmp_path / "pairs.dump").write_text(
        "ITEM: TIMESTEP\n10\nITEM: NUMBER OF ENTRIES\n1\nITEM: BOX BOUNDS\n0 1\n0 1\n0 1\nITEM: ENTRIES c_pc[1]\n"
        "1 2 0 0.5 0.1 0 1e-8\n")
    _, contacts, _ = parse(scene, tmp_path, {"dt": 1e-8})
    row = contacts[contacts["j"] == "b"].iloc[0]
    assert row["fn"] == 0 and row["ft"] == 0 and np.all(row[["fx", "fy", "fz"]].to_numpy(float) == 0)


def test_p5_yade_body_mass_scales_betan_per_material_pair():
    """'body' convention in YADE: betan x sqrt(m*_native / m*_YADE) per material pair (MatchMaker); a pair whose
    bodies need different scales is refused, naming the pair."""
    from adapters.yade.params import beta_pairs
    block = """[dem]
[dem.templates.blk]
grid = {nx = 2, ny = 3, radius = 2.5e-3}
[[dem.clusters]]
template = "blk"
material = "aluminium"
position = [0.1, 0.1, 0.0]"""
    text = BASE_SCENE.replace("[dem]", block)
    with pytest.raises(UnsupportedFeature, match=r"contacts\[aluminium, aluminium\].*P5"):   # sphere + clump, one material
        beta_pairs(loads_scene(text))
    alone = text[:text.index("[[dem.spheres]]")] + text[text.index("[[dem.planes]]"):]
    b0 = beta_restitution(0.8)
    assert beta_pairs(loads_scene(alone))[("aluminium", "aluminium")] == pytest.approx(b0 * math.sqrt(6), rel=1e-12)
    # the free sphere and the walls in materials of their own: cluster-sphere pairs get
    # sqrt(M (m + ms) / (m (M + ms))) with M = 6 m = 6 ms, i.e. sqrt(12 / 7); cluster-wall sqrt(6); sphere-wall 1
    mats = ("aluminium", "steel", "wallmat")
    three = text.replace("[materials.aluminium]", "".join(
        f"[materials.{m}]\ndensity = 2700.0\nyoung = 70e9\npoisson = 0.33\n" for m in mats[1:]) + "[materials.aluminium]")
    three = three.replace('[[contacts]]\nmaterials = ["aluminium", "aluminium"]\nrestitution = 0.8\nfriction = 0.3',
                          "\n".join(f'[[contacts]]\nmaterials = ["{a}", "{b}"]\nrestitution = 0.8\nfriction = 0.3'
                                    for i, a in enumerate(mats) for b in mats[i:]))
    three = three.replace('name = "a"\nmaterial = "aluminium"', 'name = "a"\nmaterial = "steel"')
    three = three.replace('name = "floor"\nmaterial = "aluminium"', 'name = "floor"\nmaterial = "wallmat"')
    bp = beta_pairs(loads_scene(three))
    assert bp[("aluminium", "aluminium")] == pytest.approx(b0 * math.sqrt(6), rel=1e-12)
    assert bp[("aluminium", "steel")] == pytest.approx(b0 * math.sqrt(12 / 7), rel=1e-12)
    assert bp[("aluminium", "wallmat")] == pytest.approx(b0 * math.sqrt(6), rel=1e-12)
    assert bp[("steel", "wallmat")] == pytest.approx(b0, rel=1e-12)
    assert bp[("steel", "steel")] == pytest.approx(b0, rel=1e-12)