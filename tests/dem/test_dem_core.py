"""Native DEM core: conservation, constraints, neighbour lists, determinism, blow-up detection."""
import numpy as np
import numba
import pytest

from coupler.dem.solver import DEMSolver, run_dem
from coupler.errors import SimulationError
from coupler.scene import loads_scene
from tests.conftest import BASE_SCENE, SPHERE_A, edit, scene_toml

# Two spheres colliding obliquely with spin, no gravity and no wall: only the pair contact acts.
PAIR = scene_toml("[dem]\n" + SPHERE_A + """
[[dem.spheres]]
name = "b"
material = "aluminium"
radius = 2.0e-3
position = [0.0005, 0.0075, 0.0001]
velocity = [0.3, -2.0, 0.2]
angular_velocity = [10.0, -5.0, 30.0]
""", gravity="[0.0, 0.0, 0.0]")


def test_pair_contact_conserves_linear_momentum():
    s = loads_scene(PAIR)
    assert not s.dem.planes and not s.dem.meshes                       # no wall: only the pair contact
    solver = DEMSolver(s)
    p0 = (solver.s.mass[:, None] * solver.s.v).sum(axis=0)
    solver.advance(60000)
    assert np.abs(solver.s.v[1] - s.dem.velocity[1]).max() > 0.1      # they collided
    p1 = (solver.s.mass[:, None] * solver.s.v).sum(axis=0)
    assert np.allclose(p0, p1, rtol=0, atol=1e-15)


def test_planar_scene_stays_in_plane():
    text = edit(edit(BASE_SCENE, "dimension = 3", "dimension = 2"),
                "velocity = [0.0, -1.0, 0.0]", "velocity = [2.0, -1.0, 0.0]\nangular_velocity = [0.0, 0.0, 40.0]")
    solver = DEMSolver(loads_scene(text))
    solver.advance(30000)
    assert solver.s.x[0, 2] == 0.0 and solver.s.v[0, 2] == 0.0
    assert solver.s.w[0, 0] == 0.0 and solver.s.w[0, 1] == 0.0
    assert abs(solver.s.w[0, 2] - 40.0) > 1.0   # friction acted on the spin


def _lattice(skin, rattle=0.05):
    """A 6x6x6 lattice of touching spheres in a box, rattling with seeded random velocities."""
    from coupler.bench import lattice_scene
    sc = lattice_scene(nx=6, ny=6, nz=6, steps=200)
    sc.dem.skin = skin
    sc.dem.velocity = np.random.default_rng(3).normal(scale=rattle, size=sc.dem.velocity.shape)
    return sc


def test_history_survives_neighbour_rebuilds():
    """A tiny skin forces many rebuilds; a large skin none. The physics must be identical to round-off."""
    a = DEMSolver(_lattice(1e-6))
    b = DEMSolver(_lattice(1e-3))
    a.advance(600)
    b.advance(600)
    assert a.c.rebuilds > 5 and b.c.rebuilds == 0
    assert np.allclose(a.s.x, b.s.x, rtol=0, atol=1e-15)
    assert np.allclose(a.s.v, b.s.v, rtol=1e-9, atol=1e-13)


def test_deterministic_for_thread_count_and_repeat():
    res = []
    for threads, parallel in ((1, False), (numba.config.NUMBA_NUM_THREADS, True), (1, False)):
        numba.set_num_threads(threads)
        s = DEMSolver(_lattice(2.5e-4))
        s.parallel = parallel
        s.advance(300)
        res.append(s.s.x.copy())
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(res[0], res[1]) and np.array_equal(res[0], res[2])


def test_nan_is_reported_with_step_body_quantity():
    solver = DEMSolver(loads_scene(BASE_SCENE))
    solver.s.v[0, 1] = np.nan
    solver.advance(3)
    with pytest.raises(SimulationError) as ei:
        solver.check_health()
    assert ei.value.body == "a" and ei.value.step == 3 and "position" in ei.value.quantity


def test_leaving_the_domain_is_reported():
    text = edit(BASE_SCENE, "[dem]", "[domain]\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 0.01, 0.01]\n[dem]")
    text = edit(edit(text, "velocity = [0.0, -1.0, 0.0]", "velocity = [50.0, 0.0, 0.0]"), "t_end = 1e-5", "t_end = 4e-4")
    with pytest.raises(SimulationError, match=r"body a, position: .* left the domain"):
        run_dem(loads_scene(edit(text, "dt = 1e-8", "dt = 1e-7")), None, progress=False)


def test_energy_jump_is_detected():
    """A time step far above the stable limit (bypassing the load-time check) must be caught, not run on."""
    text = edit(BASE_SCENE, "velocity = [0.0, -1.0, 0.0]", "velocity = [0.0, -5.0, 0.0]")
    scene = loads_scene(text)
    from dataclasses import replace
    scene.time = replace(scene.time, dt=2e-5, t_end=2e-3, output_interval=2e-5)
    with pytest.raises(SimulationError, match="total energy"):
        run_dem(scene, None, progress=False)


def test_result_tables_follow_the_contract(tmp_path):
    from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS, Result
    from coupler.run import run_scene
    res = run_scene(loads_scene(edit(BASE_SCENE, "t_end = 1e-5", "t_end = 1.2e-4")), tmp_path, progress=False)
    back = Result.read(tmp_path)
    assert list(back.bodies.columns) == BODY_COLUMNS
    assert list(back.contacts.columns) == CONTACT_COLUMNS
    assert list(back.energy.columns) == ENERGY_COLUMNS
    assert set(back.contacts["j"]) == {"wall:floor"}
    assert (back.contacts["fn"] >= 0).all()
    for k in ("scene", "backend", "code_version", "wall_time_s", "steps", "dt", "particles"):
        assert k in back.summary
    assert len(back.bodies) == len(res.bodies) == 121


def test_gravity_schedule_is_integrated_exactly():
    """g_y ramps linearly from 0 to -10 m/s^2 over 1 ms, then stays: y(t) has a closed form (velocity Verlet
    with g(t_n) is exact for a linear ramp up to O(dt^2))."""
    text = edit(BASE_SCENE, "gravity = [0.0, -9.81, 0.0]",
                              "gravity_schedule = [[0.0, 0.0, 0.0, 0.0], [1e-3, 0.0, -10.0, 0.0]]")
    text = edit(text, "position = [0.0, 0.0026, 0.0]", "position = [0.0, 1.0, 0.0]")
    text = edit(text, "velocity = [0.0, -1.0, 0.0]", "velocity = [0.0, 0.0, 0.0]")
    text = edit(edit(text, "t_end = 1e-5", "t_end = 2e-3"), "dt = 1e-8", "dt = 1e-7")
    scene = loads_scene(text)
    s = DEMSolver(scene)
    s.advance(20000)
    T, t = 1e-3, 2e-3
    v_exact = -10.0 * (T / 2 + (t - T))
    y_exact = 1.0 - 10.0 * (T ** 2 / 6 + T / 2 * (t - T) + 0.5 * (t - T) ** 2)
    assert s.time == pytest.approx(t, rel=1e-12)
    assert s.s.v[0, 1] == pytest.approx(v_exact, rel=1e-6)
    assert s.s.x[0, 1] == pytest.approx(y_exact, abs=1e-9)
    assert np.allclose(s.gravity, [0.0, -10.0, 0.0])
