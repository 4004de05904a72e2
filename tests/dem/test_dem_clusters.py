"""Rigid clusters: mass properties, torque-free precession, planar inertia, no self-contacts, bad input."""
import math

import numpy as np
import pytest

from coupler.dem.clusters import mass_properties
from coupler.dem.solver import DEMSolver
from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, scene_toml
from validation.metrics import sphere_mass

BASE = scene_toml("""[dem]
[dem.templates.t]
{template}
[[dem.clusters]]
name = "b"
template = "t"
material = "al"
position = [0.0, 0.0, 0.0]
angular_velocity = {omega}
""", name="c", dimension="{dim}", gravity="[0.0, 0.0, 0.0]", t_end="1e-3", dt="2e-7", output_interval="1e-4",
                  materials={"al": ALUMINIUM})
ASYM = "spheres = [[0.0, 0.0, 0.0, 2e-3], [5e-3, 0.0, 0.0, 1.5e-3], [0.0, 4e-3, 1e-3, 1e-3]]"


def scene(dim=3, template=ASYM, omega="[0.0, 0.0, 0.0]", **kw):
    return loads_scene(BASE.format(dim=dim, template=template, omega=omega))


def test_exact_mass_properties_and_voxel_agree():
    s = scene()
    t = s.dem.templates["t"]
    ex = mass_properties(t, 2700.0, "t")
    m = sphere_mass(2700.0, t.radii)
    assert ex.mass == pytest.approx(m.sum(), rel=1e-14)
    t.mass_properties, t.voxel_resolution = "voxel", 120
    vx = mass_properties(t, 2700.0, "t")
    assert vx.mass == pytest.approx(ex.mass, rel=max(3 * vx.error, 1e-3))
    assert np.allclose(vx.inertia, ex.inertia, rtol=0, atol=max(3 * vx.error, 2e-3) * np.abs(ex.inertia).max())


def test_exact_rejects_overlapping_members():
    s = scene(template="spheres = [[0.0, 0.0, 0.0, 2e-3], [3e-3, 0.0, 0.0, 2e-3]]")
    with pytest.raises(SceneError, match="members overlap"):
        DEMSolver(s)


def test_torque_free_precession_conserves_L_and_energy():
    s = scene(omega="[30.0, 200.0, -50.0]")
    solver = DEMSolver(s)
    B = solver.bodies
    L0, E0 = B.L.copy(), B.kinetic()
    assert len(set(np.round(B.Ip[0] / B.Ip[0].max(), 6))) == 3          # asymmetric body
    solver.advance(5000)
    assert np.allclose(B.L, L0, rtol=0, atol=1e-15 * np.abs(L0).max() + 1e-30)
    assert abs(B.kinetic() - E0) / E0 < 1e-5
    assert not np.allclose(B.w, solver.scene.dem.clusters[0].angular_velocity)   # it precessed


def test_planar_cluster_uses_izz_about_com():
    s = scene(dim=2, template="grid = { nx = 6, ny = 5, radius = 2.5e-3, spacing = 5e-3 }", omega="[0.0, 0.0, 10.0]")
    solver = DEMSolver(s)
    B = solver.bodies
    r, m = 2.5e-3, sphere_mass(2700.0, 2.5e-3)
    xs, ys = np.meshgrid(np.arange(6) * 5e-3 - 12.5e-3, np.arange(5) * 5e-3 - 10e-3, indexing="ij")
    izz = float(np.sum(0.4 * m * r * r + m * (xs ** 2 + ys ** 2)))
    assert B.L[0, 2] == pytest.approx(izz * 10.0, rel=1e-12)
    solver.advance(100)
    assert B.w[0, 2] == pytest.approx(10.0, rel=1e-12) and B.v[0, 2] == 0.0


def test_members_never_touch_each_other():
    s = scene(template="grid = { nx = 3, ny = 3, nz = 3, radius = 2.5e-3, spacing = 4.9e-3 }")
    s.dem.templates["t"].mass_properties = "voxel"
    solver = DEMSolver(s)
    assert len(solver.c.pj) == 0                 # overlapping members, yet no pair in the neighbour list
    solver.advance(50)
    assert np.allclose(solver.bodies.v, 0.0) and np.allclose(solver.bodies.w, 0.0)


def test_template_with_zero_spheres_is_an_error():
    with pytest.raises(SceneError, match=r"dem.templates.t.spheres: must be a non-empty list"):
        scene(template="spheres = []")


def test_drop_rebound_reproduces_liggghts_and_yade_conventions():
    """With the LIGGGHTS beta, 'body' gives the LIGGGHTS multisphere value 0.611 and 'sphere' YADE's 0.907
    (shared/notes/dem_codes.md, flat drop), through the per-contact ODE used by the validation case."""
    from coupler.dem.contact import beta_liggghts, restitution_clamped
    assert restitution_clamped(beta_liggghts(0.8) * math.sqrt(6)) == pytest.approx(0.6112, abs=5e-4)
    assert restitution_clamped(beta_liggghts(0.8) * math.sqrt(6 / 30)) == pytest.approx(0.9070, abs=5e-4)


def test_cluster_runs_are_deterministic():
    runs = []
    for _ in range(2):
        s = DEMSolver(scene(omega="[30.0, 200.0, -50.0]"))
        s.advance(500)
        runs.append((s.bodies.c.copy(), s.bodies.q.copy(), s.bodies.L.copy()))
    for a, b in zip(*runs):
        assert np.array_equal(a, b)


def test_cluster_fused_loop_identical_for_1_and_2_threads(monkeypatch):
    """Settling blocks (bench scene, 150 blocks): the parallel fused loop gives bitwise the serial result, and the
    fused loop gives bitwise the Python step loop."""
    import numba
    from coupler.dem import solver as sv
    from coupler.dem.bench_clusters import cluster_scene
    monkeypatch.setattr(sv, "PARALLEL_MIN_SPHERES", 1)
    out = []
    for threads, general in ((1, False), (2, False), (1, True)):
        numba.set_num_threads(threads)
        s = sv.DEMSolver(cluster_scene(150, 300))
        assert s.parallel == (threads > 1)
        (s._advance_general if general else s.advance)(300)
        out.append((s.bodies.c.copy(), s.bodies.q.copy(), s.bodies.L.copy(), s.s.x.copy()))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.count_nonzero(s.c.pout[:, 8] > 0) > 100           # the blocks are in contact
    for other in out[1:]:
        for a, b in zip(out[0], other):
            assert np.array_equal(a, b)
