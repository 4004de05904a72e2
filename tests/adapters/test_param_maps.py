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


def test_yade_script_hertzian_walls_and_facets_and_quaternion_order(tmp_path):
    import json
    write_yade(loads_scene(BASE_SCENE), tmp_path)
    s = (tmp_path / "run_yade.py").read_text()
    assert "Ig2_Wall_Sphere_ScGeom(hertzian=True)" in s                               # P3
    assert "Ig2_Facet_Sphere_ScGeom(hertzian=True)" in s                              # P3 for mesh walls
    assert "utils.wall" in s                                                           # P4: planes never as facets
    assert json.loads((tmp_path / "scene_yade.json").read_text())["meshes"] == []
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


def test_tilted_plane_yade_refuses_liggghts_writes_one_covering_triangle(tmp_path):
    from adapters.yade.params import check_supported
    text = BASE_SCENE.replace("normal = [0.0, 1.0, 0.0]", "normal = [0.0, 1.0, 1.0]").replace(
        "point = [0.0, 0.0, 0.0]", "point = [0.0, -0.01, 0.0]")
    with pytest.raises(UnsupportedFeature, match=r"dem.planes\[0\].normal: not supported by backend 'yade'"):
        check_supported(loads_scene(text))
    scene = loads_scene(text)
    facts = write_liggghts(scene, tmp_path)
    (w,) = facts["walls"]
    assert w["kind"] == "plane_mesh" and len(w["triangles"]) == 1
    _check_covering_triangle(w, facts["cover"], scene.time.t_end)
    s = (tmp_path / "in.liggghts").read_text()
    assert "fix mp0 all mesh/surface file plane0.stl type 1" in s
    assert "fix w0 all wall/gran model hertz tangential history mesh n_meshes 1 meshes mp0 store_force yes " \
           "limitForce on" in s                                                          # P2, P3 as primitive walls


def _check_covering_triangle(w, cover, t_end, samples=400):
    """The triangle lies in the plane and contains the plane's section of the covered region at every t."""
    import numpy as np
    n = w["normal"] / np.linalg.norm(w["normal"])
    tri0 = w["vertices"][w["triangles"][0]]
    assert np.abs((tri0 - w["point"]) @ n).max() < 1e-12
    rng = np.random.default_rng(1)
    for t in (0.0, 0.5 * t_end, t_end):
        tri = tri0 + w["velocity"] * t
        x = rng.uniform(cover[0], cover[1], (samples, 3))
        x -= np.outer((x - w["point"] - w["velocity"] * t) @ n, n)          # onto the plane at t
        inside = np.all((x >= cover[0]) & (x <= cover[1]), axis=1)
        a, b, c = tri
        for p in x[inside]:                                                # barycentric coordinates >= 0
            v0, v1, v2 = b - a, c - a, p - a
            d00, d01, d11, d20, d21 = v0 @ v0, v0 @ v1, v1 @ v1, v2 @ v0, v2 @ v1
            den = d00 * d11 - d01 * d01
            bv, bw = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
            assert min(bv, bw, 1 - bv - bw) >= -1e-9


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

# --- rigid clusters in LIGGGHTS (fix multisphere) ------------------------------------------------------------------

CLUSTER_SCENE = BASE_SCENE.replace("dimension = 3", "dimension = 2").replace(
    "[dem]", "[output]\ncontacts = false\n[dem]").replace(
    '''[[dem.spheres]]
name = "a"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0026, 0.0]
velocity = [0.0, -1.0, 0.0]''', '''[dem.templates.blk]
spheres = [[0.0, 0.0, 0.0, 2.5e-3], [5e-3, 0.0, 0.0, 2.5e-3], [5e-3, 5e-3, 0.0, 2e-3]]
[[dem.clusters]]
name = "blk"
template = "blk"
material = "aluminium"
position = [0.01, 0.02, 0.0]
angle_z = 0.3
velocity = [0.1, -0.2, 0.0]
angular_velocity = [0.0, 0.0, 5.0]''')


def test_p7_multisphere_template_has_the_exact_native_mass_inertia_and_com(tmp_path):
    """P7: no Monte Carlo. `mass` + `inertia_tensor Ixx Ixy Ixz Iyy Iyz Izz` (the order fix_template_multisphere.cpp
    reads) + `use_density`, members given relative to the exact centre of mass; 2D: planar flags."""
    import numpy as np
    from coupler.dem.clusters import mass_properties
    scene = loads_scene(CLUSTER_SCENE)
    write_liggghts(scene, tmp_path)
    s = (tmp_path / "in.liggghts").read_text()
    t = scene.dem.templates["blk"]
    mp = mass_properties(t, 2700.0, "")
    line = next(l for l in s.splitlines() if "particletemplate/multisphere" in l).split()
    assert float(line[line.index("mass") + 1]) == mp.mass
    I = [float(v) for v in line[line.index("inertia_tensor") + 1:line.index("inertia_tensor") + 7]]
    assert I == [mp.inertia[0, 0], mp.inertia[0, 1], mp.inertia[0, 2], mp.inertia[1, 1], mp.inertia[1, 2],
                 mp.inertia[2, 2]]
    assert "use_density" in line and line[line.index("type") + 1] == "1"
    assert " fflag on on off tflag off off on" in " ".join(line)                       # planar: global-frame flags
    members = np.loadtxt(tmp_path / "template1.txt")
    assert np.array_equal(members[:, :3], t.offsets - mp.center) and np.array_equal(members[:, 3], t.radii)
    ins = next(l for l in s.splitlines() if "insert/pack" in l)
    q = scene.dem.clusters[0].orientation
    assert f"orientation constant {q[0]:.17g} {q[1]:.17g} {q[2]:.17g} {q[3]:.17g}" in ins
    assert "vel constant 0.10000000000000001 -0.20000000000000001 0" in ins and "omega constant 0 0 5" in ins
    assert "fix ms all multisphere" in s and "unfix ins0" in s and "reset_timestep 0" in s


def test_p7_given_mass_properties_pass_through(tmp_path):
    text = CLUSTER_SCENE.replace('spheres = [[0.0, 0.0, 0.0, 2.5e-3], [5e-3, 0.0, 0.0, 2.5e-3], '
                                 '[5e-3, 5e-3, 0.0, 2e-3]]',
                                 'spheres = [[0.0, 0.0, 0.0, 2.5e-3], [5e-3, 0.0, 0.0, 2.5e-3]]\n'
                                 'mass_properties = "given"\nmass = 3e-4\ncenter = [2.5e-3, 0.0, 0.0]\n'
                                 'inertia = [1e-9, 2e-9, 3e-9, 0.0, 0.0, 0.0]')
    write_liggghts(loads_scene(text), tmp_path)
    s = (tmp_path / "in.liggghts").read_text()
    assert "mass 0.00029999999999999997 inertia_tensor 1.0000000000000001e-09 0 0 2.0000000000000001e-09 0 " \
           "3e-09 use_density" in s
    assert (tmp_path / "template1.txt").read_text().split()[:3] == ["-0.0025000000000000001", "0", "0"]


def _bodies_dump(rows_by_step):
    out = []
    for step, rows in rows_by_step:
        out.append(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ENTRIES\n{len(rows)}\nITEM: BOX BOUNDS mm mm mm\n"
                   "-1 1\n-1 1\n-1 1\nITEM: ENTRIES c_b_id_multisphere ...\n")
        out += [" ".join(f"{v:.17g}" for v in r) + "\n" for r in rows]
    return "".join(out)


def test_p12_p16_multisphere_orientation_and_energy_read_back(tmp_path):
    """P12: LIGGGHTS' quat is relative to the template's principal frame: the body row reports the rotation since
    t = 0 applied to the scene orientation. P16: kinetic energy from vcm, omega, angmom, not `thermo ke`."""
    import numpy as np
    from adapters.liggghts.parser import _qmul, parse
    from coupler.dem.clusters import mass_properties
    scene = loads_scene(CLUSTER_SCENE)
    c = scene.dem.clusters[0]
    q0 = np.array([0.6, 0.0, 0.0, 0.8])                              # some principal frame at t = 0
    qr = np.array([np.cos(0.25), 0.0, 0.0, np.sin(0.25)])           # then 0.5 rad about z
    q1 = _qmul(qr[None], q0[None])[0]
    w, L = np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, 2e-8])
    row0 = [1, *c.position, 0.1, -0.2, 0.0, *q0, *w, *L]
    row1 = [1, 0.02, 0.03, 0.0, 0.3, 0.4, 0.0, *q1, *w, *L]
    (tmp_path / "bodies.dump").write_text(_bodies_dump([(0, [row0]), (100, [row1])]))
    bodies, _, energy = parse(scene, tmp_path, {"dt": 1e-6})
    b = bodies[bodies["body"] == "blk"]
    assert np.allclose(b[["qw", "qx", "qy", "qz"]].iloc[0].to_numpy(float), c.orientation, atol=1e-15)
    expect = _qmul(qr[None], c.orientation[None])[0]
    assert np.allclose(b[["qw", "qx", "qy", "qz"]].iloc[1].to_numpy(float), expect, atol=1e-15)
    M = mass_properties(scene.dem.templates["blk"], 2700.0, "").mass
    assert energy["kinetic"].iloc[1] == pytest.approx(0.5 * M * 0.25 + 0.5 * 5.0 * 2e-8, rel=1e-12)
    assert energy["potential"].iloc[1] == pytest.approx(M * 9.81 * 0.03, rel=1e-12)


def test_multisphere_bodies_are_matched_to_scene_clusters_by_position(tmp_path):
    from adapters.liggghts.parser import parse
    scene = loads_scene(CLUSTER_SCENE)
    (tmp_path / "bodies.dump").write_text(_bodies_dump([(0, [[1, 0.5, 0.5, 0.0] + [0.0] * 3 + [1, 0, 0, 0]
                                                            + [0.0] * 6])]))
    with pytest.raises(RuntimeError, match="no scene cluster there"):
        parse(scene, tmp_path, {"dt": 1e-6})


# --- mesh walls and moving walls -------------------------------------------------------------------------------------

MESH_SCENE = BASE_SCENE.replace('''[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]''', '''[[dem.meshes]]
name = "floor"
material = "aluminium"
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01]]
triangles = [[0, 2, 1], [0, 3, 2]]
velocity = [0.0, 2.0, 0.0]''')


def _data_box(path):
    lines = [l.split() for l in path.read_text().splitlines() if l.endswith(("xhi", "yhi", "zhi"))]
    import numpy as np
    return np.array([float(l[0]) for l in lines]), np.array([float(l[1]) for l in lines])


def test_liggghts_mesh_wall_stl_fixes_and_box(tmp_path):
    """Scene triangles -> STL as given; fix mesh/surface + wall/gran mesh with limitForce (P2) like the primitive
    walls (R* = R, P3); a moving mesh -> move/mesh linear; every node inside the simulation box for the whole run
    (fix_mesh.cpp deletes elements outside it)."""
    import numpy as np
    scene = loads_scene(MESH_SCENE)
    write_liggghts(scene, tmp_path)
    s = (tmp_path / "in.liggghts").read_text()
    assert "fix m0 all mesh/surface file mesh0.stl type 1" in s
    assert "fix mv_m0 all move/mesh mesh m0 linear 0 2 0" in s
    assert "fix wm0 all wall/gran model hertz tangential history mesh n_meshes 1 meshes m0 store_force yes " \
           "limitForce on" in s
    assert s.index("move/mesh") < s.index("wall/gran")
    stl = [[float(v) for v in l.split()[1:]] for l in (tmp_path / "mesh0.stl").read_text().splitlines()
           if l.strip().startswith("vertex")]
    m = scene.dem.meshes[0]
    assert np.array_equal(np.array(stl), m.vertices[m.faces.ravel()])
    lo, hi = _data_box(tmp_path / "data.spheres")
    for x in (m.vertices, m.vertices + m.velocity * scene.time.t_end):
        assert np.all(x > lo) and np.all(x < hi)


def test_liggghts_moving_plane_is_a_moving_triangle(tmp_path):
    """Primitive walls take a constant position (and `shear` along one axis): a moving plane becomes one triangle
    covering the plane's section of the bodies' region at every t, moved by move/mesh; in the box for the whole run."""
    import numpy as np
    scene = loads_scene(BASE_SCENE.replace("normal = [0.0, 1.0, 0.0]",
                                           "normal = [0.0, 1.0, 0.0]\nvelocity = [3.0, 1.0, 0.0]"))
    facts = write_liggghts(scene, tmp_path)
    (w,) = facts["walls"]
    assert w["kind"] == "plane_mesh"
    _check_covering_triangle(w, facts["cover"], scene.time.t_end)
    s = (tmp_path / "in.liggghts").read_text()
    assert "fix mv_mp0 all move/mesh mesh mp0 linear 3 1 0" in s and "primitive" not in s
    lo, hi = _data_box(tmp_path / "data.spheres")
    tri = w["vertices"]
    for x in (tri, tri + w["velocity"] * scene.time.t_end):
        assert np.all(x > lo) and np.all(x < hi)


def test_2d_segments_become_strips_with_the_same_distances():
    import numpy as np
    from adapters.geometry import closest_points, mesh_triangles
    v = np.array([[-0.01, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, 0.005, 0.0]])
    seg = np.array([[0, 1], [1, 2]])
    tv, tri = mesh_triangles(v, seg, 0.05)
    assert tri.shape == (4, 3) and np.all(np.abs(tv[:, 2]) == 0.05)
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-0.02, 0.02, 200), rng.uniform(-0.01, 0.01, 200), np.zeros(200)])
    _, d = closest_points(p, tv[tri])
    a, b = v[seg[:, 0]], v[seg[:, 1]]
    t = np.clip(np.einsum("nsk,sk->ns", p[:, None] - a, b - a) / np.einsum("sk,sk->s", b - a, b - a), 0, 1)
    d_seg = np.linalg.norm(p[:, None] - (a + t[..., None] * (b - a)), axis=2).min(axis=1)
    assert np.allclose(d, d_seg, rtol=0, atol=1e-15)


def test_liggghts_mesh_contact_read_from_the_closest_point_of_the_moved_mesh(tmp_path):
    import numpy as np
    from adapters.liggghts.parser import parse
    scene = loads_scene(MESH_SCENE)
    facts = write_liggghts(scene, tmp_path)
    t = 100 * 1e-8                                          # the mesh has moved up 2 um
    y = 2.5e-3 + 2e-6 - 1e-6                               # 1 um overlap with the moved mesh
    (tmp_path / "atoms.dump").write_text(
        "ITEM: TIMESTEP\n100\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS\n0 1\n0 1\n0 1\n"
        "ITEM: ATOMS id x y z vx vy vz omegax omegay omegaz f_force_wm0[1] f_force_wm0[2] f_force_wm0[3]\n"
        f"1 0.005 {y!r} 0 0 0 0 0 0 0 0.5 3 0\n")
    _, contacts, _ = parse(scene, tmp_path, facts)
    (row,) = contacts.itertuples()
    assert row.j == "wall:floor" and row.t == pytest.approx(t)
    assert row.overlap == pytest.approx(1e-6, rel=1e-9) and row.fn == pytest.approx(3.0, rel=1e-12)
    assert row.ft == pytest.approx(0.5, rel=1e-12)


def test_liggghts_plane_mesh_region_is_checked(tmp_path):
    import numpy as np
    import pandas as pd
    from adapters.liggghts.parser import check_cover
    scene = loads_scene(BASE_SCENE)
    lo, hi = np.full(3, -0.05), np.full(3, 0.05)
    ok = pd.DataFrame({"t": [0.0], "body": ["a"], "x": [0.0], "y": [0.0], "z": [0.0]})
    check_cover(scene, ok, (lo, hi))
    with pytest.raises(RuntimeError, match="does not represent the scene"):
        check_cover(scene, ok.assign(x=0.049), (lo, hi))


def test_liggghts_deleted_mesh_elements_are_an_error(tmp_path, monkeypatch):
    """fix_mesh.cpp only warns ("Not all nodes of fix mesh inside simulation box") and deletes the elements."""
    import adapters.liggghts.backend as be
    monkeypatch.setattr(be, "find_binary", lambda name: "liggghts")

    def fake_run(cmd, cwd, log, timeout, code=None):
        (cwd / log).write_text("WARNING: Not all nodes of fix mesh inside simulation box, elements will be deleted\n")
        return 0.0
    monkeypatch.setattr(be, "run_logged", fake_run)
    with pytest.raises(RuntimeError, match="deleted mesh elements"):
        be.run(loads_scene(MESH_SCENE), tmp_path)


def test_yade_moving_walls_and_facet_meshes_written(tmp_path):
    import json
    text = MESH_SCENE + '''
[[dem.planes]]
name = "lid"
material = "aluminium"
point = [0.0, 0.02, 0.0]
normal = [0.0, -1.0, 0.0]
velocity = [0.0, -0.5, 0.0]
'''
    write_yade(loads_scene(text), tmp_path)
    P = json.loads((tmp_path / "scene_yade.json").read_text())
    assert P["walls"][0]["vel"] == [0.0, -0.5, 0.0]
    (m,) = P["meshes"]
    assert m["vel"] == [0.0, 2.0, 0.0] and m["triangles"] == [[0, 2, 1], [0, 3, 2]]
    s = (tmp_path / "run_yade.py").read_text()
    assert "b.state.vel = Vector3(*w[\"vel\"])" in s and "b.state.vel = Vector3(*m[\"vel\"])" in s
    assert "Bo1_Facet_Aabb()" in s
    # P4: the resolution runs after the InteractionLoop and before NewtonIntegrator, with the tested helpers
    assert s.index('command="p4()"') < s.index("NewtonIntegrator(")
    assert s.index("Law2_ScGeom_MindlinPhys_Mindlin()") < s.index('command="p4()"')
    assert "def resolve(feats):" in s and "O.forces.addF(sid, -fs)" in s


def test_yade_2d_mesh_becomes_strips(tmp_path):
    import json
    text = BASE_SCENE.replace("dimension = 3", "dimension = 2").replace('''[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]''', '''[[dem.meshes]]
name = "floor"
material = "aluminium"
vertices = [[-0.01, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]
segments = [[0, 1], [1, 2]]''')
    write_yade(loads_scene(text), tmp_path)
    (m,) = json.loads((tmp_path / "scene_yade.json").read_text())["meshes"]
    assert len(m["vertices"]) == 6 and len(m["triangles"]) == 4
    assert {v[2] for v in m["vertices"]} == {-0.05, 0.05}                              # 20 radii each side


def test_yade_clump_spin_and_orientation(tmp_path):
    """Clumps are aspherical: YADE integrates angMom, so the initial spin is given as L = R diag(I) R^T w; the
    reported orientation is the rotation since t = 0 applied to the scene orientation (P12), as native."""
    import json
    write_yade(loads_scene(CLUSTER_SCENE.replace("[dem]", '[dem]\ncluster_damping_mass = "sphere"')), tmp_path)
    s = (tmp_path / "run_yade.py").read_text()
    assert "st.angMom = st.ori * Vector3(wl[0] * st.inertia[0]" in s
    assert "q = s.ori * q0.conjugate() * qs" in s
    (c,) = json.loads((tmp_path / "scene_yade.json").read_text())["clusters"]
    assert c["orientation"] == pytest.approx([0.988771077936, 0.0, 0.0, 0.149438132474], abs=1e-12)


# --- P4: the native face/edge/vertex hierarchy applied to YADE facet contacts ---------------------------------------

def test_p4_feature_regions_match_the_native_closest_point():
    import numpy as np
    from adapters.yade.p4 import feature
    from coupler.dem.meshes import _closest_triangle
    rng = np.random.default_rng(7)
    for _ in range(300):
        a, b, c = rng.normal(size=(3, 3))
        p = rng.normal(size=3) * 2
        _, ftype, loc, *_ = _closest_triangle(p, a, b, c)
        assert feature(p, a, b, c) == (ftype, loc)


def test_p4_resolution_is_the_native_hierarchy():
    from adapters.yade.p4 import feature_key, resolve
    t0, t1 = [0, 2, 1], [0, 3, 2]                 # two triangles sharing the edge (0, 2)
    face0 = (0, feature_key(0, t0, 0, 0), t0)
    edge1 = (1, feature_key(1, t1, 1, 2), t1)     # edge 2 of t1 = (2, 0): the shared diagonal
    assert edge1[1] == (0, 2)
    assert resolve([face0, edge1]) == [True, False]                 # near the edge of a flat mesh: one contact
    edge0 = (1, feature_key(0, t0, 1, 0), t0)     # edge 0 of t0 = (0, 2)
    assert resolve([edge0, edge1]) == [True, False]                 # on a convex ridge: the edge counts once
    face1 = (0, feature_key(1, t1, 0, 0), t1)
    assert resolve([face0, face1]) == [True, True]                  # concave corner: two faces, two contacts
    v = [(2, feature_key(f, t, 2, t.index(0)), t) for f, t in ((0, t0), (1, t1), (2, [0, 4, 3]))]
    assert resolve(v) == [True, False, False]                       # a shared vertex counts once
    other = (1, feature_key(1, t1, 1, 0), t1)     # edge (0, 3): not an edge of t0
    assert resolve([face0, other]) == [True, True]
