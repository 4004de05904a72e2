"""MPM step contract (issue 14 section 1, /work/COORD.md): compiled advance / advance_to, point loads held until
changed, interface_state in outline order with segment index, dropped point loads counted and bounded, MPM body
table, shape registry widths and unknown ids."""
from __future__ import annotations

import json

import numpy as np
import pytest

from coupler.errors import SceneError, SimulationError
from coupler.mpm import kernels as K
from coupler.mpm import shapes
from coupler.mpm.solver import MPMSolver, run_mpm
from coupler.results import MPM_BODY_COLUMNS, Result
from coupler.scene import loads_scene

SCENE = """
name = "contract"
dimension = 2
gravity = [0.0, {g}, 0.0]
[time]
t_end = 0.02
output_interval = 0.01
[materials.m]
density = 1000.0
young = 1.0e6
poisson = 0.3
[mpm]
shape_function = "{shape}"
transfer = "{transfer}"
boundary_particles = true
{extra}
[mpm.grid]
origin = [0.0, 0.0]
size = [1.0, 1.0]
cell_size = 0.05
[mpm.boundary]
left = {{ kind = "open" }}
right = {{ kind = "open" }}
bottom = {{ kind = "open" }}
top = {{ kind = "open" }}
[[mpm.bodies]]
name = "blk"
material = "m"
rectangle = {{ min = [0.3, 0.3], max = [0.6, 0.5] }}
particles_per_cell = 2
"""


def make(g=0.0, shape="bspline2", transfer="usl", extra=""):
    return loads_scene(SCENE.format(g=g, shape=shape, transfer=transfer, extra=extra))


def _arrays(sol):
    return [sol.x, sol.v, sol.s, sol.F, sol.C, sol.vol, sol.eps_p, sol.xb, sol.vb, sol.G, sol.V]


@pytest.mark.parametrize("transfer", ["musl", "apic", "usl"])
def test_compiled_loop_equals_single_steps_and_profile_changes_nothing(transfer):
    """One compiled loop = single steps = the run cut into two calls = the profiled loop, bitwise, with held point
    loads on the boundary particles."""
    sols = [MPMSolver(make(g=-9.81, transfer=transfer)) for _ in range(4)]
    for s in sols:
        s.set_point_loads(np.tile([0.3, -0.2], (len(s.xb), 1)))
    a, b, c, d = sols
    a.advance(12)
    for _ in range(12):
        b.step()
    c.advance(12, profile=True)
    d.advance(5)
    d.advance(7)
    assert len(a.xb) > 0
    for s in (b, c, d):
        assert s.nstep == a.nstep == 12 and s.t == a.t
        for x, y in zip(_arrays(a), _arrays(s)):
            assert np.array_equal(x, y)
    timed = dict(zip(K.PHASES, c.timer))
    assert timed["p2g"] > 0 and timed["gather(g2p+stress)"] > 0
    if transfer == "musl":
        assert timed["musl_remap"] > 0
    assert (a.timer == 0).all()


def test_advance_to_equal_substeps_and_exact_clock():
    sol = MPMSolver(make())
    dt = sol.dt
    k = sol.advance_to(2.5 * dt)
    assert k == 3 and sol.nstep == 3 and sol.t == 2.5 * dt
    assert sol.advance_to(sol.t) == 0 and sol.nstep == 3
    assert sol.advance_to(sol.t + dt) == 1          # exactly one dt: one step (ceil with the 1e-9 slack)
    with pytest.raises(ValueError, match="already at"):
        sol.advance_to(0.0)
    # the k steps are equal: same state as advance(k, dt=span/k)
    a, b = MPMSolver(make(g=-9.81)), MPMSolver(make(g=-9.81))
    assert a.advance_to(0.7 * a.dt * 4) == 3          # 2.8 dt: 3 steps of 2.8 dt / 3
    b.advance(3, dt=(0.7 * b.dt * 4) / 3)
    for x, y in zip(_arrays(a), _arrays(b)):
        assert np.array_equal(x, y)


def test_point_loads_held_and_total_impulse():
    """A free block (no gravity, no walls reached), USL: the momentum of the points grows by sum(f) dt per step
    exactly (renormalised spreading keeps every load, FLIP conserves the grid impulse)."""
    sol = MPMSolver(make())
    st = sol.interface_state()
    f = np.zeros_like(st["x"])
    f[:, 0] = 2.0
    f[st["segment"] == 2, 1] = -3.0 * st["area"][st["segment"] == 2]
    sol.set_point_loads(f)
    n = 20
    sol.advance(n)
    P = (sol.m[:, None] * sol.v).sum(0)
    assert np.allclose(P, f.sum(0) * n * sol.dt, rtol=1e-10, atol=0)
    sol.apply_point_loads(np.zeros_like(f))          # alias; loads replaced, not added
    sol.advance(5)
    assert np.allclose((sol.m[:, None] * sol.v).sum(0), P, rtol=1e-10, atol=0)
    with pytest.raises(ValueError, match="shape"):
        sol.set_point_loads(np.zeros((3, 2)))
    assert sol.dropped_loads()["count"] == 0


def test_interface_state_outline_order():
    sol = MPMSolver(make())
    st = sol.interface_state()
    for key in ("x", "displacement", "velocity", "area", "body", "wall", "segment", "index", "outline"):
        assert key in st
    poly = np.array([[0.3, 0.3], [0.6, 0.3], [0.6, 0.5], [0.3, 0.5]])
    seg = st["segment"]
    assert (np.diff(seg) >= 0).all() and set(seg) == {0, 1, 2, 3}
    assert np.array_equal(st["outline"]["blk"], np.arange(len(seg)))
    # each point on its edge, in order from the edge's first vertex; tributary lengths sum to the perimeter
    for a in range(4):
        p0, p1 = poly[a], poly[(a + 1) % 4]
        e = (p1 - p0) / np.linalg.norm(p1 - p0)
        q = st["x"][seg == a] - p0
        assert np.allclose(q[:, 0] * e[1] - q[:, 1] * e[0], 0.0, atol=1e-14)
        assert (np.diff(q @ e) > 0).all()
    assert st["area"].sum() == pytest.approx(1.0, rel=1e-12)
    assert sol.boundary_particle_state()["segment"] is not None   # old name kept


def test_dropped_point_load_counted_and_bounded(tmp_path):
    sol = MPMSolver(make(extra="max_dropped_load_fraction = 0.5"))
    f = np.zeros((len(sol.xb), 2))
    f[:, 1] = -1.0
    sol.set_point_loads(f)
    sol.xb[0] = [0.9, 0.9]            # far from the body: its support holds no grid mass
    sol.advance(3)
    d = sol.dropped_loads()
    assert d["count"] == 3 and d["max_fraction"] == pytest.approx(1.0 / len(sol.xb))
    assert d["impulse_dropped"] == pytest.approx(3 * sol.dt) and d["limit"] == 0.5
    # the impulse that arrived is the applied one minus the dropped one
    P = (sol.m[:, None] * sol.v).sum(0)
    assert P[1] == pytest.approx(-(len(sol.xb) - 1) * 3 * sol.dt, rel=1e-10)
    # default limit 0.01: the same drop stops the run naming the step, the body and the particle
    sol = MPMSolver(make())
    assert sol.max_dropped_load_fraction == 0.01
    sol.set_point_loads(f)
    sol.advance(2)
    sol.xb[4] = [0.9, 0.1]
    with pytest.raises(SimulationError) as e:
        sol.advance(10)
    assert e.value.step == 3 and e.value.quantity == "point load" and e.value.body == "blk"
    assert "boundary particle 4" in str(e.value) and "max_dropped_load_fraction" in str(e.value)
    with pytest.raises(SceneError) as e:
        make(extra="max_dropped_load_fraction = 1.5")
    assert e.value.path == "mpm.max_dropped_load_fraction"


def test_mpm_body_table_and_summary(tmp_path):
    sc = make(g=-9.81)
    res = run_mpm(sc, tmp_path)
    res.summary["code_version"] = "test"     # set by coupler.run
    res.check()
    assert list(res.mpm_bodies.columns) == MPM_BODY_COLUMNS
    rows = res.mpm_body("blk")
    assert len(rows) == 3 and rows["t"].iloc[0] == 0.0
    assert rows["mass"].iloc[0] == pytest.approx(1000.0 * 0.3 * 0.2, rel=1e-12)
    last = rows.iloc[-1]
    snap = res.particles[-1][1]
    m = snap["mass"].to_numpy()
    assert last["vy"] == pytest.approx((m * snap["vy"]).sum() / m.sum(), rel=1e-12)
    assert last["kinetic"] == pytest.approx(0.5 * (m * (snap["vx"] ** 2 + snap["vy"] ** 2)).sum(), rel=1e-12)
    assert last["uy_min"] == pytest.approx(snap["uy"].min()) and last["n_points"] == len(snap)
    res.write(tmp_path)
    back = Result.read(tmp_path)
    assert list(back.mpm_bodies.columns) == MPM_BODY_COLUMNS and len(back.mpm_bodies) == 3
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["mpm_dropped_point_loads"]["count"] == 0


def test_shape_registry_width_and_unknown_id():
    assert shapes.WIDTH == (2, 3, 3) and shapes.width(shapes.LINEAR) == 2
    for name, (sid, w) in shapes.SHAPES.items():
        i0, wgt, _ = shapes.evaluate(sid, np.linspace(3.0, 5.0, 41), 0.25, 2.0, 8.0)
        assert np.allclose(wgt[:, :w].sum(1), 1.0, atol=1e-13) and (wgt[:, w:] == 0.0).all()
    with pytest.raises(ValueError, match="unknown shape function id 7"):
        shapes.check_shape(7)
    sol = MPMSolver(make(shape="linear"))
    with pytest.raises(ValueError, match="unknown shape"):
        K.strip_sort(9, sol.x, 0.0, sol.h, sol.strip_start, sol._scratch, sol.strip_order)
    sol.kind = 9
    with pytest.raises(ValueError, match="unknown shape function id 9"):
        sol.step()
    assert sol.nstep == 0


def test_particles_interval_thins_the_snapshots_only(tmp_path):
    """[output] particles_interval: MPM snapshots every that many seconds (first and last output always), the
    tables at every output time, the snapshots identical to the full run's at their times; not a multiple of the
    output interval: a scene error naming the field."""
    base = SCENE.replace("t_end = 0.02\noutput_interval = 0.01", "t_end = 0.05\noutput_interval = 0.01")
    full = run_mpm(loads_scene(base.format(g=-9.81, shape="bspline2", transfer="usl", extra="")), tmp_path / "a")
    thin_scene = loads_scene((base + "[output]\nparticles_interval = 0.02\n").format(
        g=-9.81, shape="bspline2", transfer="usl", extra=""))
    thin = run_mpm(thin_scene, tmp_path / "b")
    n = len(full.particles)                 # output times: every `every` MPM steps and the last step
    assert n >= 5 and len(thin.mpm_bodies) == len(full.mpm_bodies) == n
    keep = sorted(set(range(0, n, 2)) | {n - 1})
    assert [t for t, _ in thin.particles] == [full.particles[k][0] for k in keep]
    for (_, df), k in zip(thin.particles, keep):
        assert df.equals(full.particles[k][1])
    back = Result.read(tmp_path / "b")
    assert len(back.particles) == len(keep)
    with pytest.raises(SceneError, match="output.particles_interval"):
        loads_scene((base + "[output]\nparticles_interval = 0.015\n").format(g=-9.81, shape="bspline2",
                                                                               transfer="usl", extra=""))


@pytest.mark.parametrize("second, area", [
    ("rectangle = { min = [0.6, 0.3], max = [0.8, 0.5] }", 0.04),             # touches blk's right side
    ("rectangle = { min = [0.3, 0.5], max = [0.6, 0.7] }", 0.06),             # on top of blk
    ("rectangle = { min = [0.5, 0.3], max = [0.8, 0.5] }", None),             # 2 of blk's 6 columns shared
    ("polygon = [[0.4, 0.35], [0.5, 0.35], [0.45, 0.45]]", None),            # inside blk
])
def test_mpm_bodies_may_touch_not_overlap(second, area):
    """Two bodies seeded over one region would double its mass: a body whose points lie inside an earlier one is
    refused, naming both and the count (it was accepted before the thirty-fifth session)."""
    text = SCENE.format(g=0.0, shape="bspline2", transfer="usl", extra="") + (
        f'[[mpm.bodies]]\nname = "two"\nmaterial = "m"\n{second}\nparticles_per_cell = 2\n')
    if area is not None:
        sol = MPMSolver(loads_scene(text))                      # blk 0.3 x 0.2 m, points 0.025 m apart
        assert len(sol.x) == round((0.06 + area) / 0.025 ** 2) and len(np.unique(sol.x, axis=0)) == len(sol.x)
        return
    with pytest.raises(SceneError) as e:
        loads_scene(text)
    assert e.value.path.startswith("mpm.bodies[1].") and "overlaps body 'blk'" in str(e.value)
    assert "material points lie inside it" in str(e.value) and "\n" not in str(e.value)
