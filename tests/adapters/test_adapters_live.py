"""Live runs of LIGGGHTS and YADE through the adapters (skipped with the reason when a code is missing; a failure
in CI). The native law must reproduce each code on the same scene file."""
import pytest

from coupler.run import run_scene
from coupler.scene import load_scene
from tests.conftest import ROOT, require_binary, scene_toml

CASES = f"{ROOT}/validation/cases"


def _vs(code, scene_file, tmp_path, **over):
    require_binary(code)
    scene = load_scene(scene_file, overrides=over or None)
    nat = run_scene(scene, tmp_path / "native", progress=False)
    ref = run_scene(scene, tmp_path / code, backend=code, progress=False)
    return nat, ref


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_head_on_wall_matches(code, tmp_path):
    nat, ref = _vs(code, f"{CASES}/xval_impacts/wall.toml", tmp_path)
    assert ref.contacts["fn"].max() == pytest.approx(nat.contacts["fn"].max(), rel=1e-4)
    assert set(ref.contacts["j"]) == {"wall:floor"}
    assert ref.body("ball")["vy"].iloc[-1] == pytest.approx(nat.body("ball")["vy"].iloc[-1], rel=1e-4)  # P2: 0.800


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_pair_force_sign_and_names(code, tmp_path):
    nat, ref = _vs(code, f"{CASES}/xval_impacts/pair.toml", tmp_path)
    c = ref.contacts[ref.contacts["fn"] > 1.0]
    assert set(c["i"]) == {"a"} and set(c["j"]) == {"b"}
    assert (c["fy"] < 0).all()                     # force on a (below b) points down (P13)
    assert c["fn"].max() == pytest.approx(nat.contacts["fn"].max(), rel=1e-3)


def test_liggghts_oblique_matches_native_exactly(tmp_path):
    nat, ref = _vs("liggghts", f"{CASES}/xval_impacts/wall.toml", tmp_path,
                   **{"dem.spheres[0].velocity": [1.0, -1.0, 0.0]})
    assert ref.body("ball")["wz"].iloc[-1] == pytest.approx(nat.body("ball")["wz"].iloc[-1], rel=1e-6)


def test_yade_gross_sliding_spin_within_half_percent(tmp_path):
    nat, ref = _vs("yade", f"{CASES}/xval_impacts/wall.toml", tmp_path,
                   **{"dem.spheres[0].velocity": [3.0, -1.0, 0.0]})
    assert ref.body("ball")["wz"].iloc[-1] == pytest.approx(nat.body("ball")["wz"].iloc[-1], rel=5e-3)   # P8


@pytest.mark.parametrize("case,code,variant", [("xval_impacts", "liggghts", "wall"),
                                               ("xval_impacts", "yade", "mesh_edge"),
                                               ("xval_impacts", "liggghts", "plane_moving_oblique"),
                                               ("xval_blocks", "liggghts", "drop_body")])
def test_stored_references_are_still_reproduced(case, code, variant, tmp_path):
    """CI check: a stored reference run equals what the installed code produces now through the adapter."""
    import numpy as np
    from coupler.results import Result
    from validation.suite import discover
    require_binary(code)
    info = next(i for i in discover() if i.name == case)
    scene = info.module.reference_scenes(info.path)[variant]
    stored = Result.read(f"{ROOT}/reference_runs/{case}/{code}/{variant}")
    live = run_scene(scene, tmp_path, backend=code, progress=False)
    cols = ["x", "y", "z", "vx", "vy", "vz", "wx", "wy", "wz"]
    assert live.bodies[cols].to_numpy() == pytest.approx(stored.bodies[cols].to_numpy(), rel=1e-9, abs=1e-12)
    assert np.array_equal(live.contacts["j"].to_numpy(), stored.contacts["j"].to_numpy())
    assert live.contacts["fn"].to_numpy() == pytest.approx(stored.contacts["fn"].to_numpy(), rel=1e-9, abs=1e-9)


# --- mesh walls, moving walls ----------------------------------------------------------------------------------------

MESH = f"{CASES}/xval_impacts/mesh.toml"
WALL = f"{CASES}/xval_impacts/wall.toml"
Y_MOVING = 2.501e-3 + 1e-9            # gap not a whole number of wall steps (see xval_impacts/case.py)


def _wall_frame_restitution(res, vw):
    b = res.body("ball")
    return (b["vy"].iloc[-1] - vw) / (vw - b["vy"].iloc[0])


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_mesh_wall_head_on_matches(code, tmp_path):
    """STL / facet mesh wall, R* = R and limitForce (P2, P3): the same impact as on the plane."""
    nat, ref = _vs(code, MESH, tmp_path)
    assert set(ref.contacts["j"]) == {"wall:floor"}
    assert ref.contacts["fn"].max() == pytest.approx(nat.contacts["fn"].max(), rel=1e-6)
    assert ref.body("ball")["vy"].iloc[-1] == pytest.approx(nat.body("ball")["vy"].iloc[-1], rel=1e-6)


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_p4_impact_next_to_a_shared_edge_counts_once(code, tmp_path):
    """P4: 0.07 mm from the shared edge YADE facets alone give e = 0.738 and 41.4 N; resolved as the native
    hierarchy the impact equals the face impact (one contact at every sample)."""
    nat, ref = _vs(code, MESH, tmp_path, **{"dem.spheres[0].position": [2e-4, 2.501e-3, 1e-4]})
    assert ref.contacts.groupby("t").size().max() == 1
    assert ref.contacts["fn"].max() == pytest.approx(nat.contacts["fn"].max(), rel=1e-6)
    assert ref.body("ball")["vy"].iloc[-1] == pytest.approx(nat.body("ball")["vy"].iloc[-1], rel=1e-6)
    if code == "yade":
        assert ref.summary["p4_dropped_contact_steps"] > 1000          # the resolution did act


@pytest.mark.parametrize("code", ["liggghts", "yade"])
@pytest.mark.parametrize("wall", ["plane", "mesh"])
def test_moving_wall_head_on_matches(code, wall, tmp_path):
    key = "dem.planes[0].velocity" if wall == "plane" else "dem.meshes[0].velocity"
    x = 0.0 if wall == "plane" else 5e-3
    nat, ref = _vs(code, WALL if wall == "plane" else MESH, tmp_path, **{
        key: [0.0, 1.0, 0.0], "dem.spheres[0].velocity": [0.0, 0.0, 0.0],
        "dem.spheres[0].position": [x, Y_MOVING, 0.0]})
    assert _wall_frame_restitution(nat, 1.0) == pytest.approx(0.8, abs=1e-5)
    assert _wall_frame_restitution(ref, 1.0) == pytest.approx(_wall_frame_restitution(nat, 1.0), rel=1e-6)
    assert ref.contacts["fn"].max() == pytest.approx(nat.contacts["fn"].max(), rel=1e-6)


def test_liggghts_moving_plane_tangential_velocity_matches_exactly(tmp_path):
    """A plane moving at (3, 1, 0) m/s into a sphere at rest: the wall velocity enters the tangential law."""
    nat, ref = _vs("liggghts", WALL, tmp_path, **{
        "dem.planes[0].velocity": [3.0, 1.0, 0.0], "dem.spheres[0].velocity": [0.0, 0.0, 0.0],
        "dem.spheres[0].position": [0.0, Y_MOVING, 0.0]})
    assert ref.body("ball")["wz"].iloc[-1] == pytest.approx(nat.body("ball")["wz"].iloc[-1], rel=1e-9)


def test_liggghts_tilted_plane_matches(tmp_path):
    """A plane not normal to x, y or z (LIGGGHTS: one covering mesh triangle) hit along its normal."""
    nat, ref = _vs("liggghts", WALL, tmp_path, **{
        "dem.planes[0].normal": [0.5, 0.8660254037844386, 0.0],
        "dem.spheres[0].position": [0.0012505, 0.0021659313659, 0.0],
        "dem.spheres[0].velocity": [-0.5, -0.8660254037844386, 0.0]})
    for c in ("vx", "vy"):
        assert ref.body("ball")[c].iloc[-1] == pytest.approx(nat.body("ball")[c].iloc[-1], rel=1e-9)


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_2d_segment_mesh_over_a_shared_vertex(code, tmp_path):
    """2D segments become strips along z; the sphere lands 0.1 mm from the vertex the two segments share."""
    text = open(MESH).read()
    text = text.replace("dimension = 3", "dimension = 2").replace(
        "vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01]]",
        "vertices = [[-0.01, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]").replace(
        "triangles = [[0, 2, 1], [0, 3, 2]]", "segments = [[0, 1], [1, 2]]").replace(
        "position = [5e-3, 2.501e-3, 0.0]", "position = [1e-4, 2.501e-3, 0.0]")
    require_binary(code)
    from coupler.scene import loads_scene
    scene = loads_scene(text, name="mesh2d")
    nat = run_scene(scene, tmp_path / "native", progress=False)
    ref = run_scene(scene, tmp_path / code, backend=code, progress=False)
    assert ref.contacts.groupby("t").size().max() == 1
    assert ref.body("ball")["vy"].iloc[-1] == pytest.approx(nat.body("ball")["vy"].iloc[-1], rel=1e-6)


# --- rigid clusters ------------------------------------------------------------------------------------------------

SPIN = scene_toml("""[dem]
cluster_damping_mass = "CONV"
[dem.templates.odd]
spheres = [[0.0, 0.0, 0.0, 2.5e-3], [5e-3, 0.0, 0.0, 2.5e-3], [5e-3, 5e-3, 0.0, 2e-3], [0.0, 1e-3, 6e-3, 1.5e-3]]
[[dem.clusters]]
name = "odd"
template = "odd"
material = "aluminium"
position = [0.0, 0.05, 0.0]
orientation = [0.8, 0.2, -0.4, 0.4]
velocity = [0.1, 0.2, -0.3]
angular_velocity = [10.0, -20.0, 30.0]
""", name="spin3d", t_end="1e-2", dt="5e-7", output_interval="1e-3", output={"contacts": False})


@pytest.mark.parametrize("code,tol", [("liggghts", 1e-9), ("yade", 1e-5)])
def test_cluster_free_rotation_orientation_and_spin(code, tol, tmp_path):
    """An asymmetric 4-sphere body, general orientation and spin, free flight: exact mass and inertia (P7),
    orientation reported as native (P12), initial spin given to YADE clumps as angular momentum."""
    import numpy as np
    from coupler.scene import loads_scene
    require_binary(code)
    conv = "body" if code == "liggghts" else "sphere"          # no contact here: the damping mass plays no role (P5)
    scene = loads_scene(SPIN.replace("CONV", conv), name="spin3d")
    nat = run_scene(scene, tmp_path / "native", progress=False).body("odd")
    ref = run_scene(scene, tmp_path / code, backend=code, progress=False).body("odd")
    assert len(ref) == len(nat)
    q_n, q_r = nat[["qw", "qx", "qy", "qz"]].to_numpy(), ref[["qw", "qx", "qy", "qz"]].to_numpy()
    q_r = q_r * np.sign((q_n * q_r).sum(1))[:, None]
    assert np.abs(q_n - q_r).max() < tol
    assert np.abs(nat[["wx", "wy", "wz"]].to_numpy() - ref[["wx", "wy", "wz"]].to_numpy()).max() < 30 * tol


def test_liggghts_multisphere_flat_drop_body_damping_mass(tmp_path):
    """P5: LIGGGHTS multisphere damps with the body mass = the native "body" convention (rebound 0.598)."""
    require_binary("liggghts")
    scene = load_scene(f"{CASES}/dem_block_drop/block.toml", overrides={"dem.cluster_damping_mass": "body"})
    nat = run_scene(scene, tmp_path / "native", progress=False).body("block")
    ref = run_scene(scene, tmp_path / "liggghts", backend="liggghts", progress=False).body("block")
    rebound = lambda b: b["vy"].iloc[-1] / -b["vy"].iloc[0]            # noqa: E731
    assert rebound(ref) == pytest.approx(rebound(nat), rel=1e-6)


def test_liggghts_multisphere_tip_planar_flags(tmp_path):
    """A standing block tipping on a plane (2D: fflag/tflag; exact inertia, P7): rotation as native."""
    import numpy as np
    require_binary("liggghts")
    scene = load_scene(f"{CASES}/dem_block_tip/block.toml", overrides={"time.t_end": 0.06})
    nat = run_scene(scene, tmp_path / "native", progress=False).body("block")
    ref = run_scene(scene, tmp_path / "liggghts", backend="liggghts", progress=False).body("block")
    angle = lambda b: np.degrees(2.0 * np.arctan2(b["qz"].to_numpy(), b["qw"].to_numpy()))   # noqa: E731
    assert abs(angle(nat)[-1]) > 0.5
    assert angle(ref)[-1] == pytest.approx(angle(nat)[-1], rel=1e-5)
    z = ref["z"].to_numpy()
    assert np.all(z == z[0]) and abs(z[0]) < 2e-15          # planar; inserted within 1e-15 m of its position


MIXED = scene_toml("""[dem]
[dem.templates.b]
grid = { nx = 3, ny = 2, radius = 2.5e-3, spacing = 5e-3 }
[[dem.clusters]]
name = "block"
template = "b"
material = "aluminium"
position = [0.0, 0.0, 0.0]
[[dem.spheres]]
name = "ball"
material = "aluminium"
radius = 2.5e-3
position = [2e-4, 7.501e-3, 0.0]
velocity = [0.3, -1.0, 0.0]
""", name="mixed", dimension=2, gravity="[0.0, 0.0, 0.0]", t_end="3e-5", dt="2e-9",
                   output_interval="7e-6              # t_end is not a multiple: the final-state dumps run too",
                   output={"contacts": False})


def test_liggghts_free_sphere_hits_multisphere_body(tmp_path):
    """Free spheres beside multisphere bodies (the retaining-wall situation): sphere-member contact with the body
    mass in the damping (P5 "body"), both bodies read back, kinetic energy summed (P16)."""
    import numpy as np
    from coupler.scene import loads_scene
    require_binary("liggghts")
    scene = loads_scene(MIXED, name="mixed")
    nat = run_scene(scene, tmp_path / "native", progress=False)
    ref = run_scene(scene, tmp_path / "liggghts", backend="liggghts", progress=False)
    for body, cols in (("ball", ["vx", "vy", "wz"]), ("block", ["vx", "vy", "wz", "qz"])):
        a, b = nat.body(body)[cols].to_numpy()[-1], ref.body(body)[cols].to_numpy()[-1]
        assert np.allclose(b, a, rtol=1e-6, atol=1e-12), body
    assert ref.energy["kinetic"].iloc[-1] == pytest.approx(nat.energy["kinetic"].iloc[-1], rel=1e-6)
