"""The mesh-wall benchmark's scene (coupler/dem/bench_mesh.py): the floor it writes and reads back, and one short
native run. The throughput itself is measured by `make bench`, never asserted."""
import numpy as np

from coupler.dem.bench_mesh import CELLS, bench_mesh_native, mesh_pour_scene, terrain


def test_terrain_is_a_closed_grid_of_upward_triangles():
    nodes, faces = terrain(cells=8)
    assert nodes.shape == (81, 3) and faces.shape == (128, 3)
    a, b, c = nodes[faces[:, 0]], nodes[faces[:, 1]], nodes[faces[:, 2]]
    n = np.cross(b - a, c - a)
    assert (n[:, 1] > 0).all()                                   # every normal points up, into the beads
    area = 0.5 * np.linalg.norm(n, axis=1)
    assert area.sum() >= 0.2 ** 2                                 # covers the square (bumps add area)
    assert np.abs(nodes[:, 1]).max() <= 2e-3 + 1e-15


def test_scene_reads_the_written_stl(tmp_path):
    scene = mesh_pour_scene(tmp_path, count=10, steps=5)
    m = scene.dem.meshes[0]
    assert len(m.faces) == 2 * CELLS * CELLS and len(m.vertices) == (CELLS + 1) ** 2
    nodes, _ = terrain()
    assert np.allclose(np.sort(m.vertices[:, 1]), np.sort(nodes[:, 1]), atol=1e-9)   # STL: float32 coordinates


def test_short_native_run_touches_the_floor():
    r = bench_mesh_native(1, count=2000, steps=300)
    assert r["spheres"] == 2000 and r["steps"] == 299
    assert r["mesh_contacts"] > 0                                  # the lowest beads are on the floor
    assert 0.0 < r["mean_height_m"] < 0.05
