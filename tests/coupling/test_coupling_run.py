"""A short coupled run through the CLI writes every table; a DEM block of mass M loads the MPM with M g / thickness
per unit depth (2D units); momentum is exchanged exactly through the interface."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from coupler.results import INTERFACE_COLUMNS, Result
from coupler.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "validation" / "cases"


def _cli_run(tmp_path, text: str):
    """`mpmdem run` of a scene text in a subprocess: (CompletedProcess, output folder)."""
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(scene), "--out", str(out), "--quiet"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    return r, out


def test_cli_run_writes_the_coupled_tables(tmp_path):
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text()
    text = text.replace("t_end = 0.06", "t_end = 0.012").replace("dem_substeps = 1", "dem_substeps = 3")
    r, out = _cli_run(tmp_path, text)
    assert r.returncode == 0, r.stderr
    for f in ("bodies.csv", "contacts.csv", "energy.csv", "mpm_bodies.csv", "interface.csv", "summary.json",
              "particles_0.csv",
              "coupling_log.csv", "interface_points.csv"):
        assert (out / f).exists(), f
    assert not list(out.glob("*.vtu"))
    res = Result.read(out)
    assert list(res.interface.columns) == INTERFACE_COLUMNS
    assert len(res.interface) == res.summary["steps"] + 1
    assert set(res.bodies["body"]) == {"ball"}
    assert (res.contacts["j"] == "wall:interface").any()
    c = json.loads((out / "summary.json").read_text())["coupling"]
    assert c["dem_substeps"] == 3 and abs(c["dem_dt"] * 3 - c["coupling_dt"]) < 1e-18
    # the MPM receives what the DEM puts on the wall; momentum of both partitions is conserved
    it = res.interface
    assert np.abs(it.fx_dem - it.fx_mpm).max() <= 1e-12 * np.abs(it.fx_dem).max()
    log = pd.read_csv(out / "coupling_log.csv")
    P = log.px_dem + log.px_mpm
    assert np.abs(P - P[0]).max() <= 1e-9 * abs(P[0])
    assert log.px_mpm.iloc[-1] > 0.01 * P[0]      # the block was hit
    # the MPM body table, as an MPM-only run writes it: one row per output time, the block's mass per unit depth
    # and momentum (the coupling log's px_mpm is the same momentum x thickness)
    mb = res.mpm_body("block")
    assert list(mb.t) == list(res.energy.t) and (mb.n_points == 512).all()
    assert np.allclose(mb.mass, 1000.0 * 0.4 * 0.2, rtol=1e-12)
    assert np.allclose(mb.mass * mb.vx * c["thickness"], log.px_mpm, rtol=1e-8, atol=1e-12 * P[0])


def test_mass_per_unit_depth(tmp_path):
    """A 5-sphere cluster of 3D mass M resting on the MPM: the MPM loads (N per unit depth) sum to M g / thickness,
    i.e. the block stands for M / thickness kg per metre of depth."""
    from coupler.run import run_scene
    sc = load_scene(CASES / "coupled_resting_load" / "scene.toml",
                    overrides={"time.t_end": 0.25, "time.output_interval": 0.05})
    res = run_scene(sc, tmp_path / "rest", progress=False)
    tpl = sc.dem.templates["bar"]
    M = float(np.sum(sc.materials["steel"].density * 4 / 3 * np.pi * tpl.radii ** 3))
    th = sc.coupling.thickness
    g = -sc.gravity[1]
    it = res.interface
    late = it.t > 0.15
    assert abs(-it.fy_mpm[late].mean() / th - M * g / th) <= 2e-3 * M * g / th
    pts = pd.read_csv(tmp_path / "rest" / "interface_points.csv")
    assert abs(-pts.fy.sum() - M * g / th) <= 5e-3 * M * g / th        # N per unit depth on the MPM points


def test_linear_predictor_moves_the_wall_with_the_extrapolated_velocity(tmp_path):
    """predictor = "linear": from the second coupling step the wall velocity is 2 v_n - v_(n-1) of the MPM
    interface (constant: v_n); impulse exchange (hence momentum) is exact with either."""
    from coupler.coupling.solver import CoupledRun
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text().replace("dem_substeps = 1",
                                                                                 "dem_substeps = 2")
    from coupler.scene import loads_scene
    run = CoupledRun(loads_scene(text.replace('mapper = "nearest"', 'mapper = "nearest"\npredictor = "linear"'),
                                 name="p"))
    seen = []
    orig = run.dem.set_interface
    run.dem.set_interface = lambda x, v: (seen.append(v.copy()), orig(x, v))
    index = run.cs.geometry.index
    states = [run.mpm.interface_state()["velocity"][index]]
    for _ in range(60):          # contact starts after ~33 steps
        run.step()
        states.append(run.mpm.interface_state()["velocity"][index])
    np.testing.assert_array_equal(seen[0], states[0])
    for k in range(1, 60):
        np.testing.assert_array_equal(seen[k], 2.0 * states[k] - states[k - 1])
    assert np.abs(states[-1]).max() > 0.0
    log = run.log_row()
    assert abs(log["px_dem"] + log["px_mpm"] - run.dem.total_mass() * 1.0) <= 1e-9 * run.dem.total_mass()


def test_a_coupled_run_that_blows_up_keeps_its_tables_to_the_last_output_time(tmp_path):
    """The MPM block starts at 10 m/s towards the grid edge (0.6 m; right side at 0.4 m) and leaves the grid near
    t = 0.02 s: the run stops (exit 3, step, body and quantity) and every table is on disk up to the last output time
    before the stop (outputs every 0.003 s), readable; summary.json says where it stopped."""
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text()
    text = text.replace('constitutive = { model = "elastic" }', 'constitutive = { model = "elastic" }\n'
                        'velocity = [10.0, 0.0]')
    r, out = _cli_run(tmp_path, text)
    assert r.returncode == 3, r.stderr
    assert "block" in r.stderr and "left the grid" in r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "stopped" and "left the grid" in summary["error"]
    t_stop, t_last = summary["t"], summary["tables_end_at_t"]
    assert 0.015 < t_stop < 0.025 and t_stop - 0.003 <= t_last < t_stop
    n_out = int(round(t_last / 0.003)) + 1          # output times 0, 0.003, ..., t_last
    res = Result.read(out)                           # every table readable
    for name, df in (("bodies", res.bodies), ("energy", res.energy), ("mpm_bodies", res.mpm_bodies)):
        assert np.allclose(sorted(set(df.t)), 0.003 * np.arange(n_out), rtol=0, atol=1e-12), name
    assert len(res.particles) == n_out and abs(res.particles[-1][0] - t_last) < 1e-12
    it = res.interface
    assert list(it.columns) == INTERFACE_COLUMNS and abs(it.t.iloc[-1] - t_last) < 1e-12
    assert np.allclose(np.diff(it.t), summary["dt"], rtol=1e-9)       # one row per coupling step, none missing
    for f in ("coupling_log.csv", "interface_series.csv", "interface_wall.csv"):
        df = pd.read_csv(out / f)
        assert abs(df.t.iloc[-1] - t_last) < 1e-12 and df.t.nunique() == n_out, f
    assert set(res.bodies.body) == {"ball"} and res.body("ball").x.iloc[0] == -0.055


def test_automatic_coupling_step_keeps_the_interface_contact_stable():
    """issue 17: a stiff DEM contact on a soft explicit MPM body sets the coupling step (coupling/step_limit.py);
    where the MPM's CFL step is the smaller one (every validated coupled scene) it stays, and a scene's own
    coupling.dt is kept."""
    from coupler.coupling.solver import CoupledRun
    from coupler.coupling.step_limit import interface_step_limit
    from coupler.dem.timestep import chosen_dt
    hard = load_scene(CASES / "hard_coupled" / "scene.toml")
    lim, why = interface_step_limit(hard)
    run = CoupledRun(hard)
    assert run.dt == lim < chosen_dt(hard) and run.substeps == 1 and "MPM surface node" in run.dt_limit
    # hard_coupled's sweep: stable at 2 DEM steps, chatter at 4; the rule's step lies below
    assert lim < 2 * chosen_dt(hard)
    forced = load_scene(CASES / "hard_coupled" / "scene.toml", overrides={"coupling.dt": 4e-4 * 0.5})
    assert CoupledRun(forced).dt == 2e-4
    rest = load_scene(CASES / "coupled_resting_load" / "scene.toml")
    run = CoupledRun(rest)
    assert run.dt_limit == "" and interface_step_limit(rest)[0] > run.dt


def test_particles_interval_in_a_coupled_run(tmp_path):
    """[output] particles_interval thins the MPM snapshots of a coupled run (first and last output kept); the
    interface and body tables keep every output time."""
    from coupler.coupling.solver import run_coupled
    from coupler.scene import loads_scene
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text().replace("t_end = 0.06", "t_end = 0.015")
    sc = loads_scene(text + "\n[output]\nparticles_interval = 0.006\n", base_dir=CASES / "coupled_free_collision")
    res = run_coupled(sc, tmp_path / "thin", progress=False)
    ts = sorted(set(res.bodies["t"].round(9)))
    assert len(ts) == 6
    assert [round(t, 9) for t, _ in res.particles] == [ts[0], ts[2], ts[4], ts[5]]
    assert len(list((tmp_path / "thin").glob("particles_*.csv"))) == 4


def test_gravity_schedule_is_refused_in_a_coupled_run(tmp_path):
    """The MPM solver has a constant gravity: a coupled scene with gravity_schedule is refused before it runs, as
    an MPM-only one (before the thirty-fifth session it ran, the DEM under the schedule and the MPM under a constant
    gravity)."""
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text().replace(
        "gravity = [0.0, 0.0, 0.0]", "gravity_schedule = [[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, -9.81, 0.0]]")
    r, out = _cli_run(tmp_path, text)
    assert r.returncode == 2, r.stderr
    assert "gravity_schedule: not supported by backend 'native (MPM)'" in r.stderr
    assert not (out / "bodies.csv").exists()


def test_output_energy_false_is_honoured_by_coupled_and_mpm_runs(tmp_path):
    """[output] energy = false: energy.csv holds the header only, as in a DEM run (coupled and MPM-only runs wrote
    every row before the thirty-fifth session); the coupling log keeps each partition's energies."""
    from coupler.mpm.solver import run_mpm
    from coupler.run import run_scene
    from coupler.scene import loads_scene
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text().replace("t_end = 0.06", "t_end = 0.009")
    res = run_scene(loads_scene(text + "\n[output]\nenergy = false\n"), tmp_path / "c", progress=False)
    assert len(res.energy) == 0 and (tmp_path / "c" / "energy.csv").read_text() == "t,kinetic,potential,elastic,dissipated\n"
    assert len(pd.read_csv(tmp_path / "c" / "coupling_log.csv")) == 4                     # t = 0, .003, .006, .009
    mpm = (CASES / "mpm_elastic_bar" / "scene.toml").read_text()
    for energy, rows in (("false", 0), ("true", None)):
        res = run_mpm(loads_scene(mpm + f"\n[output]\nenergy = {energy}\n"), tmp_path / energy, progress=False)
        got = pd.read_csv(tmp_path / energy / "energy.csv")
        assert len(got) == len(res.energy) == (rows if rows is not None else len(res.mpm_bodies))
