"""Mesh walls: one contact across shared edges/vertices, node forces sum to contact forces, moving nodes,
bad input."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from coupler.dem.solver import DEMSolver
from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, edit, scene_toml

SCENE = scene_toml("""[dem]
[[dem.spheres]]
name = "s"
material = "al"
radius = 2.5e-3
position = {pos}
velocity = [0.0, 0.0, 0.0]
[[dem.meshes]]
name = "floor"
material = "al"
velocity = {mvel}
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01], [0.0, 0.0, 0.0]]
triangles = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]]
""", name="m", t_end="1e-3", dt="2e-7", output_interval="1e-4", materials={"al": ALUMINIUM})


PLANE = """[[dem.planes]]
name = "floor"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
"""


def solver(pos="[0.0, 0.002499, 0.0]", mvel="[0.0, 0.0, 0.0]"):
    return DEMSolver(loads_scene(SCENE.format(pos=pos, mvel=mvel)))


@pytest.mark.parametrize("pos", ["[0.0, 0.002499, 0.0]",          # on the shared vertex of four triangles
                                 "[0.002, 0.002499, 0.002]",      # on the shared edge of two triangles
                                 "[0.004, 0.002499, 0.001]"])     # inside one face
def test_one_contact_at_shared_vertex_edge_and_face(pos):
    """Wherever the sphere meets the flat mesh (shared vertex, shared edge, inside a face) the contact is the one
    a plane wall at the same height gives (an independent code path: coupler/dem/forces.py plane contacts)."""
    s = solver(pos)
    s.advance(10)
    plane = SCENE.format(pos=pos, mvel="[0.0, 0.0, 0.0]")
    plane = plane[:plane.index("[[dem.meshes]]")] + PLANE
    ref = DEMSolver(loads_scene(plane))
    ref.advance(10)
    assert len(s.mesh_out[0]) == 1                                  # one contact, not one per triangle touched
    c = ref.c
    w = c.wout[c.wout[:, 8] > 0.0]                                  # the plane contact row: F(3), ..., F_n, F_t, overlap
    assert len(w) == 1
    for col, pcol, what in ((2, 1, "F_y"), (4, 6, "F_n"), (6, 8, "overlap")):   # mesh_out row: i, F(3), F_n, |F_t|, overlap
        assert s.mesh_out[0][0, col] == pytest.approx(w[0, pcol], rel=1e-9), what
    assert s.mesh_out[0][0, 4] > 0.0
    assert np.allclose(s.s.v, ref.s.v, rtol=1e-9, atol=1e-15)


def test_node_forces_sum_to_contact_forces():
    s = solver("[0.0013, 0.002499, 0.0021]")
    s.advance(10)
    total_contact = s.mesh_out[0][:, 1:4].sum(axis=0)
    nodes = s.mesh_node_forces("floor", average=False)   # this step's node forces (default: time average)
    assert np.allclose(nodes.sum(axis=0), -total_contact, rtol=1e-13, atol=1e-16)
    assert np.count_nonzero(np.abs(nodes).sum(axis=1)) == 3       # spread over the nodes of one triangle


def test_moving_mesh_drags_the_sphere():
    s = solver("[0.004, 0.00249, 0.001]", mvel="[0.3, 0.0, 0.0]")
    s.advance(2000)
    assert s.s.v[0, 0] > 0.01                                      # friction with the moving nodes
    assert s.meshes[0].x[0, 0] == pytest.approx(-0.01 + 0.3 * 2000 * 2e-7)


def test_set_mesh_nodes_is_used_by_the_contact():
    s = solver("[0.004, 0.0026, 0.001]")
    m = s.meshes[0]
    s.set_mesh_nodes("floor", m.x + [0.0, 2e-4, 0.0], np.zeros_like(m.x))
    s.advance(1)
    assert s.mesh_out[0][0, 6] == pytest.approx(1e-4, rel=1e-2)   # overlap against the moved nodes


def test_static_mesh_jump_is_seen_by_the_rebuild_test():
    """A static mesh (v = 0) moved by set_mesh_nodes is 'moving' until the next neighbour build (its nodes are away
    from their build positions): a jump far beyond the skin still brings the contact at the next step."""
    s = solver("[0.004, 0.0126, 0.001]")                           # 10 mm above the floor: no candidate faces
    assert s.skin < 0.01
    m = s.meshes[0]
    s.advance(1)
    assert len(s.mesh_out[0]) == 0
    rebuilds = s.c.rebuilds
    s.set_mesh_nodes("floor", m.x + [0.0, s.s.x[0, 1] - 2.4e-3, 0.0], np.zeros_like(m.x))  # 0.1 mm in
    s.advance(1)
    assert s.c.rebuilds == rebuilds + 1
    assert len(s.mesh_out[0]) == 1
    assert s.mesh_out[0][0, 6] == pytest.approx(1e-4, rel=2e-2)


def test_static_mesh_nodes_stay_and_do_no_work():
    s = solver("[0.004, 0.002499, 0.001]")
    x0 = s.meshes[0].x.copy()
    s.advance(500)
    assert np.array_equal(s.meshes[0].x, x0)
    assert s.mesh_work("floor") == 0.0
    assert not s._M.moving[0]


def test_node_forces_follow_the_contact_across_faces():
    """A sphere sliding over the shared edge and vertex of the floor: at every step the non-zero node forces are
    those of the faces it touches (the nodes of the previous step are cleared) and sum to minus the contact force;
    after it lifts off every node force is exactly zero."""
    s = solver("[-0.0012, 0.00249, 0.0005]")
    faces = s.meshes[0].faces.tolist()
    seen = set()
    for _ in range(24):                      # across three faces: x < 0, then z > |x|, then x > 0
        s.s.x[0, 1], s.s.v[0] = 0.00249, [40.0, 0.0, 0.0]         # held at 10 um overlap, sliding along x
        s.advance(10)
        out = s.mesh_out[0]
        nodes = s.mesh_node_forces("floor", average=False)
        assert len(out) == 1
        assert np.allclose(nodes.sum(axis=0), -out[:, 1:4].sum(axis=0), rtol=1e-12, atol=1e-16)
        touched = set(np.flatnonzero(np.abs(nodes).sum(axis=1)).tolist())
        on = [k for k, f in enumerate(faces) if touched <= set(f)]
        assert 1 <= len(touched) <= 3 and on
        seen.add(tuple(sorted(touched)))
    assert len(seen) >= 3
    s.s.v[0] = [0.0, 50.0, 0.0]
    s.advance(200)
    assert len(s.mesh_out[0]) == 0
    assert not s.mesh_node_forces("floor", average=False).any()


def test_static_mesh_faces_binned_once_and_rebinned_after_a_move():
    """The binned faces of a static mesh are kept between neighbour builds, rebuilt when its nodes moved; the
    candidates are always those of a fresh search (the rule of meshes.candidates_reference)."""
    from coupler.dem import meshes as msh
    s = solver("[0.004, 0.00249, 0.001]")
    first = s._mesh_bins[0]
    for _ in range(3):
        s.s.v[0] = [30.0, 0.0, 0.0]                                # far enough to force neighbour builds
        s.advance(200)
    assert s.c.rebuilds >= 2 and s._mesh_bins[0] is first
    m = s.meshes[0]
    s.set_mesh_nodes("floor", m.x + [s.skin, 0.0, 0.0], np.zeros_like(m.x))     # beyond half the skin
    s.advance(1)
    assert s._mesh_bins[0] is not first
    off, cand = msh.candidates_reference(s.s.x, s.s.r, m, s.skin)
    assert np.array_equal(s._M.cand_off[0], off) and np.array_equal(s._M.cand, cand)


def test_degenerate_triangle_is_an_error():
    text = edit(SCENE.format(pos="[0.0, 0.01, 0.0]", mvel="[0.0, 0.0, 0.0]"),
                "[3, 4, 0]]", "[3, 4, 0], [0, 4, 2]]")
    with pytest.raises(SceneError, match="degenerate triangle"):
        loads_scene(text)


def test_unreadable_mesh_file_is_an_error(tmp_path):
    (tmp_path / "bad.stl").write_text("not a mesh")
    text = SCENE.format(pos="[0.0, 0.01, 0.0]", mvel="[0.0, 0.0, 0.0]")
    text = text[:text.index("vertices =")] + 'file = "bad.stl"\n'
    from coupler.scene import parse_scene
    import tomllib
    with pytest.raises(SceneError, match=r"dem.meshes\[0\].file: cannot read mesh file"):
        parse_scene(tomllib.loads(text), base_dir=tmp_path)


def test_mesh_from_stl_file(tmp_path):
    import meshio
    pts = np.array([[-0.01, 0, -0.01], [0.01, 0, -0.01], [0.01, 0, 0.01], [-0.01, 0, 0.01]], float)
    meshio.write(tmp_path / "floor.stl", meshio.Mesh(pts, [("triangle", np.array([[0, 2, 1], [0, 3, 2]]))]))
    text = SCENE.format(pos="[0.004, 0.002499, 0.001]", mvel="[0.0, 0.0, 0.0]")
    text = text[:text.index("vertices =")] + 'file = "floor.stl"\n'
    from coupler.scene import parse_scene
    import tomllib
    sc = parse_scene(tomllib.loads(text), base_dir=tmp_path)
    s = DEMSolver(sc)
    s.advance(10)
    assert len(s.mesh_out[0]) == 1


# -- the closest-point kernels (scalar, meshes.closest_triangle / closest_segment) against a numpy statement of
# Ericson's algorithm (Real-Time Collision Detection 5.1.5), the array code they replaced: every Voronoi region
def _ref_triangle(p, a, b, c):
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0.0 and d2 <= 0.0:
        return a, 2, 0, (1.0, 0.0, 0.0)
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0.0 and d4 <= d3:
        return b, 2, 1, (0.0, 1.0, 0.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a + v * ab, 1, 0, (1.0 - v, v, 0.0)
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0.0 and d5 <= d6:
        return c, 2, 2, (0.0, 0.0, 1.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a + w * ac, 1, 2, (1.0 - w, 0.0, w)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b + w * (c - b), 1, 1, (0.0, 1.0 - w, w)
    denom = 1.0 / (va + vb + vc)
    v, w = vb * denom, vc * denom
    return a + ab * v + ac * w, 0, 0, (1.0 - v - w, v, w)


COORD = st.floats(-1.0, 1.0, allow_nan=False)
VEC = st.tuples(COORD, COORD, COORD)


@settings(max_examples=300, deadline=None)
@given(VEC, VEC, VEC, VEC)
def test_closest_triangle_matches_the_reference(p, a, b, c):
    from coupler.dem.meshes import closest_triangle
    p, a, b, c = (np.array(v) for v in (p, a, b, c))
    if np.linalg.norm(np.cross(b - a, c - a)) < 1e-6:
        return                                                  # degenerate triangles are refused by the scene
    q, ft, loc, bary = _ref_triangle(p, a, b, c)
    got = closest_triangle(*p, *a, *b, *c)
    assert got[3:5] == (ft, loc)
    assert np.allclose(got[:3], q, rtol=0, atol=1e-12) and np.allclose(got[5:], bary, rtol=0, atol=1e-9)
    # the point is the barycentric combination of the corners
    assert np.allclose(got[5] * a + got[6] * b + got[7] * c, got[:3], atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(VEC, VEC, VEC)
def test_closest_segment_is_the_projection_clamped(p, a, b):
    from coupler.dem.meshes import closest_segment
    p, a, b = (np.array(v) for v in (p, a, b))
    if np.linalg.norm(b - a) < 1e-6:
        return
    t = float(np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0))
    got = closest_segment(*p, *a, *b)
    assert np.allclose(got[:3], a + t * (b - a), atol=1e-12)
    assert got[3] == (2 if t in (0.0, 1.0) else 0) and np.isclose(got[6], t, atol=1e-12)
