"""Issue 17 item 7 (DEM): nothing is dropped silently. A sphere meeting more mesh features than the per-sphere
buffer (64) or more distinct contacts than its history slots (4) is counted and reported in summary.json
(`mesh_contacts_dropped`); energies() includes the elastic energy stored in the sphere-mesh contacts."""
import json
import math

import numpy as np
import pytest

from coupler.dem.solver import DEMSolver, run_dem
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, scene_toml

R = 2.5e-3
C = np.array([0.0, 0.01, 0.0])


def _directions(n: int, lower_only: bool) -> np.ndarray:
    """n well-spread unit vectors (Fibonacci sphere; the lower hemisphere only when lower_only)."""
    k = np.arange(n) + 0.5
    y = -k / n if lower_only else 1.0 - 2.0 * k / n
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    rho = np.sqrt(1.0 - y * y)
    return np.stack([rho * np.cos(phi), y, rho * np.sin(phi)], axis=1)


def pit_scene(n_faces: int, lower_only: bool = True) -> str:
    """n_faces small disjoint triangles, each tangent to the sphere (overlap 1e-7 m) at a different direction."""
    verts, tris = [], []
    s = 0.08 * R
    for u in _directions(n_faces, lower_only):
        a = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(u, a)
        p = C + (R - 1e-7) * u
        k = len(verts)
        verts += [p + s * a, p - 0.5 * s * a + 0.87 * s * b, p - 0.5 * s * a - 0.87 * s * b]
        tris.append([k, k + 1, k + 2])
    vtxt = "[" + ", ".join("[" + ", ".join(repr(float(c)) for c in v) + "]" for v in verts) + "]"
    body = f"""[dem]
max_initial_overlap = 0.05
[[dem.spheres]]
name = "s"
material = "al"
radius = {R!r}
position = [{float(C[0])!r}, {float(C[1])!r}, {float(C[2])!r}]
[[dem.meshes]]
name = "pit"
material = "al"
vertices = {vtxt}
triangles = {tris}
"""
    return scene_toml(body, name="pit", gravity="[0.0, 0.0, 0.0]", t_end="2e-8", dt="1e-8",
                      output_interval="1e-8", materials={"al": ALUMINIUM})


def test_more_contacts_than_slots_are_counted_and_reported(tmp_path):
    s = DEMSolver(loads_scene(pit_scene(6)))
    assert s.mesh_drops()["pit"] == {"features_beyond_buffer": 0, "contacts_beyond_slots": 2, "rows_beyond_buffer": 0}
    res = run_dem(loads_scene(pit_scene(6)), tmp_path, progress=False)
    d = json.loads((tmp_path / "summary.json").read_text())["mesh_contacts_dropped"]
    assert d["pit"]["contacts_beyond_slots"] == res.summary["mesh_contacts_dropped"]["pit"]["contacts_beyond_slots"]
    assert d["pit"]["contacts_beyond_slots"] == 2 * 3            # forces at t = 0 and two steps, 2 dropped each
    assert d["total"] == 6


def test_more_features_than_the_buffer_are_counted():
    s = DEMSolver(loads_scene(pit_scene(70, lower_only=False)))
    d = s.mesh_drops()["pit"]
    assert d["features_beyond_buffer"] == 70 - 64
    assert d["contacts_beyond_slots"] == 64 - 4


def test_no_drops_in_an_ordinary_mesh_contact():
    s = DEMSolver(loads_scene(pit_scene(3)))
    s.advance(1)
    assert s.mesh_drops()["pit"] == {"features_beyond_buffer": 0, "contacts_beyond_slots": 0, "rows_beyond_buffer": 0}
    assert len(s.mesh_out[0]) == 3


def _on(wall: str) -> DEMSolver:
    w = {"plane": '[[dem.planes]]\nname = "floor"\nmaterial = "al"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\n',
         "mesh": '[[dem.meshes]]\nname = "floor"\nmaterial = "al"\n'
                 'vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01]]\n'
                 'triangles = [[0, 2, 1], [0, 3, 2]]\n'}[wall]
    body = f'[dem]\n[[dem.spheres]]\nname = "s"\nmaterial = "al"\nradius = {R!r}\nposition = [0.0021, {R + 1e-6!r}, 0.0013]\n' \
           'velocity = [0.0, -1.0, 0.0]\n' + w
    return DEMSolver(loads_scene(scene_toml(body, gravity="[0.0, 0.0, 0.0]", t_end="1e-5", dt="1e-9",
                                            output_interval="1e-6", materials={"al": ALUMINIUM})))


def test_energies_include_the_mesh_contact_elastic_energy():
    plane, mesh = _on("plane"), _on("mesh")
    plane.advance(4000)
    mesh.advance(4000)
    assert mesh.mesh_elastic_energy() > 0.0
    e_plane, e_mesh = plane.energies(), mesh.energies()
    assert e_mesh[2] == pytest.approx(e_plane[2], rel=1e-9)          # the same contact, the same stored energy
    assert e_mesh[0] + e_mesh[2] + e_mesh[3] == pytest.approx(0.5 * mesh.s.mass[0] * 1.0, rel=1e-6)
