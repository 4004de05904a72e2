"""The DEM step contract the coupler uses (COORD / issue 14 section 1): set_time_step, advance_to, moving mesh
nodes feeding the neighbour rebuild, time-averaged node forces, mesh work, the energy balance with moving walls,
prescribed cluster motion (scene and run time), compiled mesh candidates."""
import math

import numpy as np
import pytest

from coupler.dem import meshes as msh
from coupler.dem.solver import DEMSolver, run_dem
from coupler.errors import SceneError, SimulationError
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, scene_toml

HEAD = scene_toml("[dem]\n", name="k", gravity="{g}", t_end="1e-3", dt="2e-7", output_interval="1e-4",
                  materials={"al": ALUMINIUM}, output={"energy": "true"})     # gravity filled in by .format
SPHERE = """
[[dem.spheres]]
name = "s"
material = "al"
radius = 2.5e-3
position = {pos}
velocity = {vel}
"""
FLOOR = """
[[dem.meshes]]
name = "floor"
material = "al"
velocity = {mvel}
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01], [0.0, 0.0, 0.0]]
triangles = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]]
"""
BLOCK = """
[dem.templates.t]
spheres = [[-2e-3, 0.0, 0.0, 2e-3], [2e-3, 0.0, 0.0, 2e-3]]
[[dem.clusters]]
name = "b"
template = "t"
material = "al"
position = {bpos}
velocity = {bvel}
{motion}
"""
NOG = "[0.0, 0.0, 0.0]"
G = "[0.0, -9.81, 0.0]"


def mesh_scene(pos="[0.004, 0.0026, 0.001]", vel=NOG, mvel=NOG, g=NOG):
    return loads_scene(HEAD.format(g=g) + SPHERE.format(pos=pos, vel=vel) + FLOOR.format(mvel=mvel))


def block_scene(motion="", bpos="[0.0, 0.01, 0.0]", bvel=NOG, g=G, sphere=True, pos="[0.0, 0.0145, 0.0]",
                vel="[0.0, -0.5, 0.0]"):
    text = HEAD.format(g=g) + BLOCK.format(bpos=bpos, bvel=bvel, motion=motion)
    if sphere:
        text += SPHERE.format(pos=pos, vel=vel)
    return loads_scene(text)


# -- time stepping ---------------------------------------------------------------------------------------------

def test_set_time_step_and_advance_to():
    s = DEMSolver(mesh_scene())
    dt0 = s.dt
    with pytest.raises(ValueError, match="stable limit"):
        s.set_time_step(2.0 * s.dt_limit)
    s.set_time_step(dt0 / 4)
    s.advance_to(3 * dt0)
    assert s.nstep == 12 and s.time == pytest.approx(3 * dt0, rel=1e-14)
    with pytest.raises(SimulationError, match="solver time mismatch"):
        s.advance_to(s.time + 0.5 * s.dt)
    with pytest.raises(SimulationError, match="solver time mismatch"):
        s.advance_to(s.time - s.dt)
    s.advance_to(s.time + 1e-13 * s.dt)            # within 1e-9 relative: zero steps
    assert s.nstep == 12


# -- moving mesh nodes and the neighbour rebuild ---------------------------------------------------------------

def test_nodes_moved_into_a_sphere_make_a_contact():
    """The sphere is 2 mm above the mesh (farther than r + skin: no candidate faces). Nodes moved up into it must
    be seen at the next step (rebuild on the actual node displacement, not a wall speed fixed at construction)."""
    s = DEMSolver(mesh_scene(pos="[0.004, 0.0045, 0.001]"))
    assert s.skin < 2e-3 and len(s.mesh_out[0]) == 0
    m = s.meshes[0]
    before = s.c.rebuilds
    s.set_mesh_nodes("floor", m.x + [0.0, 2.1e-3, 0.0], np.zeros_like(m.x))
    s.advance(1)
    assert s.c.rebuilds > before
    assert len(s.mesh_out[0]) == 1
    assert s.mesh_out[0][0, 6] == pytest.approx(1e-4, rel=1e-2)


def test_drifting_nodes_push_the_sphere():
    """Nodes set moving up at 1 m/s (the mesh was static at construction) lift the sphere resting 1 mm above."""
    s = DEMSolver(mesh_scene(pos="[0.004, 0.0035, 0.001]"))
    m = s.meshes[0]
    s.set_mesh_nodes("floor", m.x.copy(), np.tile([0.0, 1.0, 0.0], (len(m.x), 1)))
    s.advance(10000)                                # 2 ms: the nodes travel 2 mm
    assert m.x[0, 1] == pytest.approx(2e-3, rel=1e-9)
    assert s.s.v[0, 1] > 0.5                        # pushed along, not passed through
    assert s.s.x[0, 1] > m.x[0, 1] + 2.4e-3


# -- node forces and work --------------------------------------------------------------------------------------

def test_node_forces_constant_force_average_is_that_force():
    """A fixed one-block cluster pressed 1e-5 m into a static mesh: the same contact force every step, so the
    time average equals the force of every step."""
    text = HEAD.format(g=NOG) + BLOCK.format(bpos="[0.004, 0.00199, 0.001]", bvel=NOG,
                                             motion='motion = { kind = "fixed" }') + FLOOR.format(mvel=NOG)
    s = DEMSolver(loads_scene(text))
    snap = s.mesh_node_forces("floor")
    assert np.abs(snap).sum() > 0.0
    s.advance(7)
    avg = s.mesh_node_forces("floor")
    assert np.allclose(avg, s.mesh_node_forces("floor", average=False), rtol=1e-12, atol=0.0)
    assert np.allclose(avg, snap, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("calls", [1, 3])
def test_node_force_impulse_equals_sphere_momentum_change(calls):
    """No gravity, a sphere bouncing on the mesh: over each advance call, (time-averaged node force) x duration
    equals minus the sphere's momentum change (velocity Verlet impulse, trapezoid over the steps)."""
    s = DEMSolver(mesh_scene(pos="[0.0013, 0.00251, 0.0021]", vel="[0.1, -0.5, 0.0]"))
    mass = s.s.mass[0]
    per_call = 2400 // calls                         # the contact lasts ~10 us = 50 steps; 0.48 ms in total
    seen = 0.0
    for _ in range(calls):
        v0 = s.s.v[0].copy()
        s.advance(per_call)
        impulse = s.mesh_node_forces("floor").sum(axis=0) * per_call * s.dt
        dp = mass * (s.s.v[0] - v0)
        seen = max(seen, np.abs(dp).max())
        assert np.allclose(impulse, -dp, rtol=1e-9, atol=1e-12 * mass)
    assert seen > 0.9 * mass * 0.5                  # the bounce happened in the window


def test_mesh_work_closes_the_energy_balance():
    """A mesh moving up at 0.5 m/s hits a sphere at rest (no gravity): the work of the spheres on the nodes is
    minus the energy the sphere received (kinetic + stored elastic + dissipated)."""
    s = DEMSolver(mesh_scene(pos="[0.004, 0.0027, 0.001]", mvel="[0.0, 0.5, 0.0]"))
    s.advance(5000)
    k, p, e, d = s.energies()
    w = s.mesh_work("floor")
    assert k > 1e-6
    assert w < 0.0
    assert k + d + s.mesh_elastic_energy() == pytest.approx(-w, rel=2e-3)
    assert s.work_input() == pytest.approx(-w, rel=1e-12)


def test_energy_check_runs_with_moving_walls(tmp_path):
    """With a moving plane the energy check is not skipped: K + P + E + D - (work of the walls) stays constant, and
    the run passes."""
    text = HEAD.format(g=G).replace("t_end = 1e-3", "t_end = 2e-3") + SPHERE.format(
        pos="[0.0, 0.004, 0.0]", vel=NOG) + """
[[dem.planes]]
name = "piston"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
velocity = [0.2, 1.0, 0.0]
"""
    res = run_dem(loads_scene(text), progress=False)
    e = res.energy
    assert e["kinetic"].iloc[-1] > 1e-6            # the piston hit the sphere
    s = DEMSolver(loads_scene(text))
    start = sum(s.energies())
    s.advance(10000)
    bal = sum(s.energies()) - s.work_input()
    assert s.work_input() > 0.0
    assert bal == pytest.approx(start, abs=2e-3 * s.work_input())


# -- prescribed cluster motion ---------------------------------------------------------------------------------

def test_fixed_cluster_holds_and_reports_its_reaction():
    s = DEMSolver(block_scene('motion = { kind = "fixed" }', pos="[0.0, 0.0143, 0.0]"))
    c0, q0 = s.bodies.c.copy(), s.bodies.q.copy()
    rows = []
    for _ in range(400):                             # the sphere lands on the block after ~2400 steps
        s.advance(10)
        ii, jj, data = s.contact_rows()
        rows = [k for k, (a, b) in enumerate(zip(ii, jj)) if {a, b} == {"s", "b"}]
        if rows:
            break
    assert rows, "the sphere-block contact is in the contacts table"
    assert data[rows, 3].max() > 0.0                 # normal force of the contact on the fixed block
    assert np.array_equal(s.bodies.c, c0) and np.array_equal(s.bodies.q, q0)
    assert np.all(s.bodies.v == 0.0) and np.all(s.bodies.w == 0.0)
    assert abs(s.bodies.F[0, 1]) > 0.0              # reaction of the contact (+ weight) reported on the body


def test_prescribed_velocity_until_then_free():
    motion = 'motion = { kind = "velocity", velocity = [0.1, 0.0, 0.0], angular_velocity = [0.0, 0.0, 5.0], until = 4e-4 }'
    s = DEMSolver(block_scene(motion, sphere=False))
    c0 = s.bodies.c.copy()
    s.advance(1000)                                  # t = 2e-4: still prescribed, gravity does not act
    assert s.bodies.c[0] == pytest.approx(c0[0] + [0.1 * 2e-4, 0.0, 0.0], abs=1e-14)
    assert np.allclose(s.bodies.w[0], [0.0, 0.0, 5.0])
    angle = 2.0 * math.atan2(s.bodies.reported_q()[0, 3], s.bodies.reported_q()[0, 0])
    assert angle == pytest.approx(5.0 * 2e-4, rel=1e-9)
    s.advance(2000)                                  # free from t = 4e-4: falls under gravity
    assert s.bodies.v[0, 0] == pytest.approx(0.1, rel=1e-12)
    assert s.bodies.v[0, 1] == pytest.approx(-9.81 * 2e-4, rel=1e-9)


def test_set_body_motion_at_run_time_and_its_work_in_the_balance():
    """A block pushed up at 0.3 m/s into a sphere at rest above it: the prescription does work; the balance
    K + P + E + D - work_input stays at its start value."""
    s = DEMSolver(block_scene(sphere=True, g=NOG, pos="[0.0, 0.0143, 0.0]", vel=NOG))
    s.set_body_motion("b", "velocity", velocity=[0.0, 0.3, 0.0])
    start = sum(s.energies())
    s.advance(5000)
    assert s.bodies.v[0, 1] == 0.3
    assert s.s.v[0, 1] > 0.3                         # the sphere was hit
    w = s.work_input()
    assert w > 0.0
    assert sum(s.energies()) - w == pytest.approx(start, abs=2e-3 * w)
    s.set_body_motion("b", "fixed")
    s.advance(10)
    assert np.all(s.bodies.v == 0.0)
    s.set_body_motion("b", "free")
    with pytest.raises(ValueError, match="no cluster named"):
        s.set_body_motion("nope", "fixed")
    with pytest.raises(ValueError, match="kind must be"):
        s.set_body_motion("b", "glued")


@pytest.mark.parametrize("motion, field, text", [
    ('motion = { kind = "pinned" }', "dem.clusters[0].motion.kind", "must be one of"),
    ('motion = { kind = "fixed", velocity = [1.0, 0.0, 0.0] }', "dem.clusters[0].motion.velocity", "fixed"),
    ('motion = { kind = "velocity", until = -1.0 }', "dem.clusters[0].motion.until", ">= 0"),
    ('motion = { kind = "velocity", speed = 1.0 }', "dem.clusters[0].motion.speed", "unknown"),
    ('motion = "fixed"', "dem.clusters[0].motion", "table"),
])
def test_bad_motion_is_a_scene_error(motion, field, text):
    with pytest.raises(SceneError) as e:
        block_scene(motion)
    assert field in str(e.value) and text in str(e.value)


def test_planar_motion_must_stay_in_plane():
    text = (HEAD.format(g=G).replace("dimension = 3", "dimension = 2")
            + BLOCK.format(bpos="[0.0, 0.01, 0.0]", bvel=NOG,
                           motion='motion = { kind = "velocity", velocity = [0.0, 0.0, 1.0] }'))
    with pytest.raises(SceneError, match=r"dem.clusters\[0\].motion.velocity\[2\]"):
        loads_scene(text)


# -- compiled candidate search ---------------------------------------------------------------------------------

def test_binned_candidates_equal_the_reference_rule():
    rng = np.random.default_rng(3)
    nv = 30
    verts = rng.uniform(-0.02, 0.02, (nv, 3))
    faces = np.array([rng.choice(nv, 3, replace=False) for _ in range(60)], np.int64)
    mesh = msh.build_mesh("m", 0, verts, faces, np.zeros(3), 400)
    x = rng.uniform(-0.03, 0.03, (400, 3))
    r = rng.uniform(1e-3, 4e-3, 400)
    off, cand = msh.candidates(x, r, mesh, 5e-4)
    roff, rcand = msh.candidates_reference(x, r, mesh, 5e-4)
    assert np.array_equal(off, roff) and np.array_equal(cand, rcand)
    assert len(cand) > 50
    grid = msh.bin_faces(mesh.x, mesh.faces, msh.max_reach(r, 5e-4), len(x))     # the parallel flavour: the same
    poff, pcand = msh.query_faces_par(x, r, 5e-4, grid, mesh.x, mesh.faces)
    assert np.array_equal(poff, off) and np.array_equal(pcand, cand)
    fx = mesh.x[mesh.faces]                  # the distance rule keeps fewer faces than the boxes grown by r + skin
    boxes = sum(np.all((x[i] >= fx.min(1) - r[i] - 5e-4) & (x[i] <= fx.max(1) + r[i] + 5e-4), axis=1).sum()
                for i in range(len(x)))
    assert len(cand) < boxes
