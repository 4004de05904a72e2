"""The t = 0 overlap check (coupler/dem/scene.py check_initial_overlap, coupler/coupling/scene.py start_overlap)
covers every sphere the solver will have: free spheres, cluster members, and every wall: planes, meshes
(triangles, segments) and the coupling interface (the MPM body's outline).
A deep start overlap flings the bodies apart (a 2D block placed 5 radii into its floor left at 50 m/s)."""
from pathlib import Path

import pytest

from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import FLOOR, edit, scene_toml

ROOT = Path(__file__).resolve().parents[2]

# a 2 x 3 block of touching spheres (R = 2.5 mm); its centre of mass is its centre, 2.5 + 5 = 7.5 mm above its
# lowest member centre, so position y = 0.010 rests on the floor
BLOCK = """[dem.templates.block]
spheres = [[0.0, 0.0, 0.0, 2.5e-3], [5e-3, 0.0, 0.0, 2.5e-3], [0.0, 5e-3, 0.0, 2.5e-3], [5e-3, 5e-3, 0.0, 2.5e-3],
           [0.0, 1e-2, 0.0, 2.5e-3], [5e-3, 1e-2, 0.0, 2.5e-3]]
"""


def cluster(name: str, x: float, y: float) -> str:
    return f'[[dem.clusters]]\nname = "{name}"\ntemplate = "block"\nmaterial = "aluminium"\nposition = [{x!r}, {y!r}, 0.0]\n'


def blocks_scene(*clusters: str, extra: str = "") -> str:
    return scene_toml("[dem]\n" + BLOCK + "".join(clusters) + extra + FLOOR, dt=None)


def refusal(text: str) -> str:
    with pytest.raises(SceneError) as e:
        loads_scene(text)
    assert e.value.path == "dem.max_initial_overlap"
    assert "\n" not in str(e.value)
    return str(e.value)


def test_resting_blocks_are_accepted():
    # on the floor and side by side, touching (members of one cluster overlap nothing of another)
    sc = loads_scene(blocks_scene(cluster("a", 0.0, 0.0075), cluster("b", 0.01, 0.0075)))
    assert [c.name for c in sc.dem.clusters] == ["a", "b"]


def test_cluster_in_its_floor_is_refused():
    msg = refusal(blocks_scene(cluster("a", 0.0, 0.0050)))             # 2.5 mm into the floor: 1 radius
    assert "cluster 'a' overlaps wall 'floor' by 1 of the radius" in msg, msg


def test_two_clusters_overlapping_are_refused():
    msg = refusal(blocks_scene(cluster("a", 0.0, 0.0075), cluster("b", 0.009, 0.0075)))   # 1 mm: 0.4 radius
    assert "cluster 'a' and cluster 'b' overlap by 0.4 of the radius" in msg, msg


def test_members_of_one_cluster_may_overlap():
    text = blocks_scene(cluster("a", 0.0, 0.0075)).replace("[5e-3, 0.0, 0.0, 2.5e-3]", "[3e-3, 0.0, 0.0, 2.5e-3]")
    assert len(loads_scene(text).dem.clusters) == 1


def test_free_sphere_inside_a_cluster_is_refused():
    sphere = '[[dem.spheres]]\nname = "s"\nmaterial = "aluminium"\nradius = 2.5e-3\nposition = [0.0, 0.0165, 0.0]\n'
    msg = refusal(blocks_scene(cluster("a", 0.0025, 0.0075), extra=sphere))   # 4 mm above the top member: 0.4
    assert "sphere 's' and cluster 'a'" in msg or "cluster 'a' and sphere 's'" in msg, msg


TRIANGLE = """[[dem.meshes]]
name = "ramp"
material = "aluminium"
vertices = [[-0.1, 0.05, -0.1], [0.1, 0.05, -0.1], [0.0, 0.05, 0.1]]
triangles = [[0, 1, 2]]
"""


@pytest.mark.parametrize("x, y, z, ok", [
    (0.0, 0.0526, 0.0, True),          # above the face, 0.1 mm gap
    (0.0, 0.0520, 0.0, False),         # 0.5 mm into the face: 0.2 radius
    (0.0, 0.0480, 0.0, False),         # from below (a mesh wall has no inside)
    (0.0, 0.0500, 0.1015, False),      # beyond the apex (0, 0.05, 0.1), 1.5 mm away: a vertex contact
    (0.0, 0.0500, 0.1026, True),       # 2.6 mm beyond it
])
def test_sphere_against_a_triangle(x, y, z, ok):
    sphere = f'[[dem.spheres]]\nname = "s"\nmaterial = "aluminium"\nradius = 2.5e-3\nposition = [{x}, {y}, {z}]\n'
    text = scene_toml("[dem]\n" + sphere + TRIANGLE, dt=None)
    if ok:
        assert loads_scene(text).dem.meshes[0].name == "ramp"
    else:
        assert "sphere 's' overlaps wall 'ramp'" in refusal(text)


def test_cluster_against_a_2d_segment_wall():
    seg = ('[[dem.meshes]]\nname = "step"\nmaterial = "aluminium"\n'
           'vertices = [[0.005, 0.0, 0.0], [0.005, 0.05, 0.0]]\nsegments = [[0, 1]]\n')
    ok = scene_toml("[dem]\n" + BLOCK + cluster("a", 0.0, 0.0075) + seg + FLOOR, dimension=2, dt=None)
    bad = edit(ok, "[[0.005, 0.0, 0.0], [0.005, 0.05, 0.0]]", "[[0.003, 0.0, 0.0], [0.003, 0.05, 0.0]]")
    assert len(loads_scene(ok).dem.meshes) == 1                      # touching the right members (x = 2.5 + 2.5 mm)
    assert "cluster 'a' overlaps wall 'step' by 0.8 of the radius" in refusal(bad)


def test_sphere_in_the_coupling_interface_is_refused():
    base = (ROOT / "validation/cases/coupled_free_collision/scene.toml").read_text()
    assert loads_scene(base).coupling is not None                    # the ball 5 mm off the block's outline
    msg = refusal(edit(base, "position = [-0.055, 0.1, 0.0]", "position = [-0.045, 0.1, 0.0]"))
    assert "sphere 'ball' overlaps the coupling interface (the outline of MPM body 'block') by 0.1" in msg, msg
    # deep inside the block (0.1 m from every edge, r = 0.05): no overlap with the outline, but inside the soil
    msg = refusal(edit(base, "position = [-0.055, 0.1, 0.0]", "position = [0.2, 0.1, 0.0]"))
    assert "sphere 'ball' starts inside MPM body 'block'" in msg, msg


def test_the_interface_walls_corner_cut_is_reported_not_refused():
    # coupled_retaining_wall at h = 10 mm: the wall through the boundary particles cuts the staircase's inner
    # corners, where a block's corner sphere rests on the outline (0 overlap with the outline itself)
    text = (ROOT / "validation/cases/coupled_retaining_wall/scene.toml").read_text()
    assert "cell_size = 0.0025" in text
    fine = loads_scene(text).coupling.start_overlap
    coarse = loads_scene(edit(text, "cell_size = 0.0025", "cell_size = 0.01")).coupling.start_overlap
    assert fine["spheres_over_tolerance"] == 0 and fine["largest_fraction_of_radius"] < 1e-12
    assert coarse["spheres_over_tolerance"] == 5
    assert coarse["largest_fraction_of_radius"] == pytest.approx(0.3598, abs=1e-4)
