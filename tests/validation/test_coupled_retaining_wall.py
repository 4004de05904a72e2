"""The coupled retaining wall case (issue 15) on a short version of its scene: the run completes with its tables
(bodies, interface, energy, MPM snapshots, VTK), the blocks are held until the release, and the failure-mode
metrics and rows of the case are computed from them. (Whether the wall collapses as in the experiment is the
validation case's job: the short run only reaches the first instants after the release.)"""
import importlib
import math

import numpy as np
import pandas as pd

from validation.framework import CASES_DIR, CaseContext

CASE = importlib.import_module("validation.cases.coupled_retaining_wall.case")
T_REL, T_END, CELL = 0.02, 0.05, 0.01
SHORT = {"time.t_end": T_END, "time.output_interval": 0.01,
         **{f"dem.clusters[{k}].motion.until": T_REL for k in range(6)}}


def test_short_coupled_wall_has_tables_and_failure_metrics(tmp_path, monkeypatch):
    monkeypatch.setattr(CASE, "QUICK", SHORT)
    ctx = CaseContext("coupled_retaining_wall", CASES_DIR / "coupled_retaining_wall", tmp_path)
    scene = CASE._scene(ctx, CELL, vtk=True)
    assert CASE.t_release(scene) == T_REL and scene.coupling.edges == list(range(1, 12))
    res = ctx.run(scene, tag="short")
    out = tmp_path / "short"
    for f in ("bodies.csv", "interface.csv", "energy.csv", "coupling_log.csv", "interface_points.csv",
              "summary.json"):
        assert (out / f).exists(), f
    assert any((out / "vtk").iterdir())
    it = res.interface
    assert len(it) == res.summary["steps"] + 1 and np.isfinite(it[["fx_dem", "fy_dem"]].to_numpy()).all()
    assert float(it["fx_dem"].abs().max()) > 0.0           # the backfill pushes on the held blocks
    hist = CASE.block_histories(res)
    for name in CASE.BLOCKS:
        t, x, y, a = hist[name]
        assert T_END <= t[-1] < T_END + 0.01
        held = t <= T_REL - 1e-9
        assert np.all(x[held] == x[0]) and np.all(a[held] == 0.0)    # fixed until the release
    m = CASE.failure_metrics(hist, T_REL)
    assert len(m["separation"]) == 5 and all(math.isfinite(s) for s in m["separation"])
    assert all(math.isfinite(m[n][k]) for n in CASE.BLOCKS for k in ("dx", "dy", "rot_max", "lift_max"))
    CASE.check_failure_mode(ctx, m, ctx.wall_times["short"])
    names = [r.metric for r in ctx.rows]
    assert "bottom block max |rotation| [deg]" in names and "blocks separate: smallest joint opening [-min, m]" in names
    assert len(names) == 6 + 1 + 2 + 2 * 5 + 1 and all(math.isfinite(r.value) for r in ctx.rows)
    row = CASE.final_row(hist)
    assert set(row) == {f"{q}_final_{n}" for q in ("x", "y", "rot") for n in CASE.BLOCKS}
    xs, s = CASE.final_surface(res.particles[-1][1], CELL, scene.mpm.bodies[0].particles_per_cell, 0.6)
    assert 0.14 < s.max() < 0.16
    assert {"mpm", "dem"} <= set(res.summary["coupling"]["cost_s"])
    pd.DataFrame([row]).to_csv(tmp_path / "row.csv")


def test_a_resolution_run_that_stops_is_a_failing_row_read_back(tmp_path, monkeypatch):
    """--full resolution runs (case._run_or_stopped): a run that stops is reported as a failing row naming the error
    and its tables up to the last output time are read back (here: a short run's tables, then a forced stop)."""
    from coupler.errors import SimulationError
    monkeypatch.setattr(CASE, "QUICK", SHORT)
    ctx = CaseContext("coupled_retaining_wall", CASES_DIR / "coupled_retaining_wall", tmp_path)
    scene = CASE._scene(ctx, CELL)
    done = CASE._run_or_stopped(ctx, scene, "h10mm")          # completes: no row
    assert not ctx.rows and float(done.bodies["t"].max()) >= T_END - 1e-9

    def stop(*a, **k):
        raise SimulationError(7, 0.03, "backfill", "point load", "forced stop")
    monkeypatch.setattr(ctx, "run", stop)
    r = CASE._run_or_stopped(ctx, scene, "h10mm")
    assert len(ctx.rows) == 1 and not ctx.rows[0].passed and "forced stop" in ctx.rows[0].note
    assert ctx.rows[0].metric == "h10mm: run stops before t_end [stops]"
    assert np.allclose(r.bodies["t"].unique(), done.bodies["t"].unique(), rtol=1e-9)     # CSV: 10 digits


def test_coupled_streamed_tables_equal_the_whole_table_writer(tmp_path, monkeypatch):
    """A finished coupled run keeps the tables it wrote as it went (Result.streamed: not written a second time):
    byte for byte what Result.write makes of the whole run (contact rows and MPM snapshots included)."""
    from coupler.run import run_scene
    monkeypatch.setattr(CASE, "QUICK", {**SHORT, "output.contacts": True, "output.particles_interval": 0.02})
    ctx = CaseContext("coupled_retaining_wall", CASES_DIR / "coupled_retaining_wall", tmp_path)
    res = run_scene(CASE._scene(ctx, CELL), tmp_path / "streamed", progress=False)
    assert res.streamed is not None and len(res.contacts) > 0 and len(res.particles) == 4     # 0, .02, .04, .05 s
    res.streamed = None
    res.write(tmp_path / "whole")
    files = sorted(p.name for p in (tmp_path / "whole").glob("*.csv"))
    assert {"bodies.csv", "contacts.csv", "energy.csv", "mpm_bodies.csv", "interface.csv", "particles_3.csv"} <= set(files)
    for f in files:
        assert (tmp_path / "streamed" / f).read_bytes() == (tmp_path / "whole" / f).read_bytes(), f


def test_ensemble_perturbs_the_coupling_step_itself(tmp_path, monkeypatch):
    """run_ensemble varies coupling.dt (member 0 the scene unchanged): at h = 10 mm the coupling step is the interface
    contact limit, not the MPM CFL step, so perturbing mpm.cfl left the 8 members bitwise one run."""
    from coupler.coupling.partitions import MPMPartition
    from coupler.coupling.solver import CoupledRun
    from coupler.coupling.step_limit import interface_step_limit
    monkeypatch.setattr(CASE, "QUICK", SHORT)
    ctx = CaseContext("coupled_retaining_wall", CASES_DIR / "coupled_retaining_wall", tmp_path)
    sc = CASE._scene(ctx, CELL)
    lim = interface_step_limit(sc)[0]
    assert CASE.coupling_step(sc) == lim < MPMPartition(sc, None).dt
    assert CoupledRun(sc).dt == lim
    jobs = []

    class Stop(Exception):
        pass

    def capture(j, **kw):
        jobs.extend(j)
        raise Stop
    monkeypatch.setattr(ctx, "run_many", capture)
    try:
        CASE.run_ensemble(ctx, CELL, "ens")
    except Stop:
        pass
    assert len(jobs) == CASE.N_ENSEMBLE and jobs[0][0].coupling.dt is None
    dts = [CoupledRun(s).dt for s, _ in jobs[:3]]
    assert dts == [lim, lim * (1 - CASE.ENSEMBLE_REL), lim * (1 - 2 * CASE.ENSEMBLE_REL)]
