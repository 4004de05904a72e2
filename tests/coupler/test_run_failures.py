"""Issue 17, runs that fail: a blow-up (a body leaving the domain, an energy jump, a material point leaving the grid,
an implicit step that does not converge) stops the run with step, body and quantity, and every table written up to
the last output time stays on disk, readable (pandas, Result.read) and consistent; the same after a SIGKILL of the
command-line run midway (coupler/results.py ResultStream, used by the DEM and MPM run loops)."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from coupler.errors import SimulationError
from coupler.results import Result
from coupler.run import run_scene
from coupler.scene import loads_scene
from tests.conftest import ROOT, SPHERE_ON_FLOOR, scene_toml

# DEM: a sphere in free flight (no gravity) along +x leaves the domain at x = 0.05 m about halfway through the run.
LEAVER = scene_toml("""[domain]
min = [-0.1, -0.1, -0.1]
max = [0.05, 0.1, 0.1]
[dem]
[[dem.spheres]]
name = "runaway"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0, 0.0]
velocity = [1.0, 0.0, 0.0]
[[dem.spheres]]
name = "still"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.05, 0.0]
""", gravity="[0.0, 0.0, 0.0]", t_end="0.1", dt=None, output_interval="1e-3")

# DEM: an elastic sphere dropped onto a floor; the test forces a time step 100x the stable limit (as a wrong limit
# would), so the impact at t = 0.05 s blows up the energy (the load-time check refuses such a dt in a scene file).
DROP = scene_toml("""[dem]
[[dem.spheres]]
name = "ball"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0126, 0.0]
[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
""", t_end="0.1", dt="1e-7", output_interval="5e-3", contacts=[("aluminium", "aluminium", "1.0", "0.3")])

# MPM: an elastic block moving at 5 m/s towards an open right side: its points leave the grid at about t = 0.05 s.
MPM_LEAVER = """
name = "mpm_leaver"
dimension = 2
gravity = [0.0, 0.0, 0.0]
[time]
t_end = 0.2
output_interval = 0.01
[materials.bar]
density = 1000.0
young = 1e5
poisson = 0.2
[mpm]
shape_function = "linear"
[mpm.grid]
origin = [0.0, 0.0]
size = [0.5, 0.1]
cell_size = 0.02
[mpm.boundary]
right = { kind = "open" }
[[mpm.bodies]]
name = "block"
material = "bar"
rectangle = { min = [0.02, 0.02], max = [0.22, 0.08] }
velocity = [5.0, 0.0]
"""

# implicit MPM: a block falling onto a slip floor; with one Newton iteration and no step cuts allowed, the free
# fall converges and the impact step (the wall's active set changes) does not.
IMPLICIT_DROP = """
name = "implicit_drop"
dimension = 2
gravity = [0.0, -9.81, 0.0]
[time]
t_end = 0.4
output_interval = 0.02
[materials.soil]
density = 2000.0
young = 1e6
poisson = 0.3
[mpm]
scheme = "implicit"
shape_function = "linear"
[mpm.implicit]
max_iter = 1
max_cuts = 0
[mpm.grid]
origin = [0.0, 0.0]
size = [0.4, 0.6]
cell_size = 0.02
[[mpm.bodies]]
name = "block"
material = "soil"
rectangle = { min = [0.1, 0.3], max = [0.3, 0.4] }
"""


def _check_tables(out: Path, interval: float, t_stop: float | None = None) -> float:
    """The tables in `out` are readable (pandas, Result.read), every table's times are the output grid from 0 up
    to its last time, the tables agree up to the earliest last time (they differ by at most one output time, a kill
    between two tables' writes) and, for a blow-up, end at the last output time before it. Returns that time."""
    res = Result.read(out)
    dt = res.summary["dt"]
    tables = {"energy": res.energy}
    if len(res.bodies):
        tables["bodies"] = res.bodies
    if len(res.mpm_bodies):
        tables["mpm_bodies"] = res.mpm_bodies
    lasts = {}
    for name, df in tables.items():
        t = np.unique(df["t"].to_numpy())
        assert len(t) >= 2, f"{name}: fewer than two output times on disk"
        gaps = np.diff(t)              # every output time from 0 on, round(interval / dt) steps apart
        assert t[0] == 0.0 and np.allclose(gaps, gaps[0], rtol=1e-6, atol=0.0), f"{name}: output times {t}"
        assert gaps[0] == pytest.approx(max(1, round(interval / dt)) * dt, rel=1e-6), (name, gaps[0], interval, dt)
        assert not df.drop(columns=[c for c in ("body", "dissipated", "elastic") if c in df]).isna().any().any(), \
            f"{name}: a NaN on disk"
        lasts[name] = t[-1]
        gap = gaps[0]
    common = min(lasts.values())
    assert max(lasts.values()) - common <= gap * (1 + 1e-6), f"tables more than one output apart: {lasts}"
    n_per = {name: df[df["t"] <= common + 1e-12].groupby("t").size() for name, df in tables.items()}
    for name, sizes in n_per.items():
        assert sizes.nunique() == 1, f"{name}: an output time with missing rows: {sizes.to_dict()}"
    if t_stop is not None:     # a blow-up: every table ends at the last output time before it
        assert len(set(lasts.values())) == 1, lasts
        assert common <= t_stop <= common + gap * (1 + 1e-6), (common, t_stop)
    for p in sorted(out.glob("particles_*.csv")):
        pd.read_csv(p)
    return common


def _stopped(out: Path, err: SimulationError) -> dict:
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "stopped"
    assert summary["step"] == err.step and summary["body"] == err.body and summary["quantity"] == err.quantity
    return summary


def test_dem_body_leaving_the_domain_keeps_the_tables(tmp_path):
    with pytest.raises(SimulationError) as e:
        run_scene(loads_scene(LEAVER), tmp_path, progress=False)
    err = e.value
    assert err.body == "runaway" and err.quantity == "position" and 0.04 < err.t < 0.06, str(err)
    s = _stopped(tmp_path, err)
    last = _check_tables(tmp_path, 1e-3, err.t)
    assert s["t_last_output"] == pytest.approx(last)
    assert last > 0.04                              # about half of the run is on disk
    b = Result.read(tmp_path).body("runaway")        # and it is the run's trajectory
    np.testing.assert_allclose(b["x"], b["t"], rtol=1e-9, atol=1e-12)


def test_dem_energy_jump_keeps_the_tables(tmp_path):
    from coupler.dem.solver import run_dem
    from coupler.dem.timestep import stable_dt
    scene = loads_scene(DROP)
    scene.time = dataclasses.replace(scene.time, dt=100 * stable_dt(scene)[0])   # past the load-time check
    with pytest.raises(SimulationError) as e:
        run_dem(scene, tmp_path, progress=False)
    err = e.value
    assert err.quantity == "total energy" and err.t > 0.045, str(err)
    _stopped(tmp_path, err)
    assert _check_tables(tmp_path, 5e-3, err.t) >= 0.04     # the fall (0.05 s) is on disk


def test_mpm_point_leaving_the_grid_keeps_the_tables(tmp_path):
    with pytest.raises(SimulationError) as e:
        run_scene(loads_scene(MPM_LEAVER), tmp_path, progress=False)
    err = e.value
    assert err.body == "block" and "left the grid" in err.quantity and 0.03 < err.t < 0.08, str(err)
    _stopped(tmp_path, err)
    last = _check_tables(tmp_path, 0.01, err.t)
    assert len(list(tmp_path.glob("particles_*.csv"))) == round(last / 0.01) + 1


def test_implicit_mpm_non_converging_step_keeps_the_tables(tmp_path):
    with pytest.raises(SimulationError) as e:
        run_scene(loads_scene(IMPLICIT_DROP), tmp_path, progress=False)
    err = e.value
    assert err.quantity == "Newton iteration" and err.t > 0.1, str(err)
    _stopped(tmp_path, err)
    _check_tables(tmp_path, 0.02, err.t)


def test_cli_blow_up_exit_3_one_line(tmp_path):
    (tmp_path / "s.toml").write_text(LEAVER)
    p = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(tmp_path / "s.toml"), "--out",
                        str(tmp_path / "out"), "--quiet"], capture_output=True, text=True, cwd=ROOT, timeout=600,
                       env=dict(os.environ, PYTHONPATH=ROOT))
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 3 and len(lines) == 1, p.stderr
    assert "body runaway, position" in lines[0] and str(tmp_path / "out") in lines[0], lines[0]
    _check_tables(tmp_path / "out", 1e-3)


# -- SIGKILL midway: the command-line run is killed after its first output rows appear --------------------------------
LONG_DEM = LEAVER.replace("t_end = 0.1", "t_end = 1e3").replace('max = [0.05, 0.1, 0.1]', 'max = [1e4, 0.1, 0.1]') \
    .replace("velocity = [1.0, 0.0, 0.0]", "velocity = [1e-3, 0.0, 0.0]")
LONG_MPM = MPM_LEAVER.replace("t_end = 0.2", "t_end = 1e3").replace("velocity = [5.0, 0.0]", "velocity = [0.0, 0.0]") \
    .replace("output_interval = 0.01", "output_interval = 0.002")
LONG_IMPLICIT = IMPLICIT_DROP.replace("max_iter = 1", "max_iter = 25").replace("max_cuts = 0", "max_cuts = 4") \
    .replace("t_end = 0.4", "t_end = 1e3")


@pytest.mark.parametrize("text,interval", [(LONG_DEM, 1e-3), (LONG_MPM, 0.002), (LONG_IMPLICIT, 0.02)],
                         ids=["dem", "mpm-explicit", "mpm-implicit"])
def test_sigkill_midway_leaves_readable_tables(text, interval, tmp_path):
    (tmp_path / "s.toml").write_text(text)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "coupler.cli", "run", str(tmp_path / "s.toml"), "--out", str(out),
                             "--quiet"], cwd=ROOT, env=dict(os.environ, PYTHONPATH=ROOT),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 900            # includes a cold numba compile on a loaded machine
        energy = out / "energy.csv"
        while time.monotonic() < deadline and proc.poll() is None:
            if energy.exists() and energy.stat().st_size and len(energy.read_bytes().splitlines()) > 6:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"the run ended before it could be killed: {proc.stderr.read()[-2000:]}"
        time.sleep(0.5)                                  # kill it while it writes
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert json.loads((out / "summary.json").read_text())["status"] == "running"
    _check_tables(out, interval)


# -- the streamed tables are the tables: byte for byte what Result.write makes of the whole run -----------------------
@pytest.mark.parametrize("text", [
    scene_toml(SPHERE_ON_FLOOR, t_end="2e-4", output_interval="1e-6"),  # DEM with contact rows (impact)
    MPM_LEAVER.replace("t_end = 0.2", "t_end = 0.03"),                  # explicit MPM, particle snapshots
    IMPLICIT_DROP.replace("max_iter = 1", "max_iter = 25").replace("t_end = 0.4", "t_end = 0.06"),
], ids=["dem", "mpm-explicit", "mpm-implicit"])
def test_streamed_tables_equal_the_whole_table_writer(text, tmp_path):
    res = run_scene(loads_scene(text), tmp_path / "streamed", progress=False)
    assert res.streamed is not None
    res.streamed = None
    res.write(tmp_path / "whole")
    files = sorted(p.name for p in (tmp_path / "whole").glob("*.csv"))
    assert files == sorted(p.name for p in (tmp_path / "streamed").glob("*.csv"))
    assert len(files) >= 3 and (len(res.contacts) > 0 or len(res.mpm_bodies) > 0)
    for f in files:
        assert (tmp_path / "streamed" / f).read_bytes() == (tmp_path / "whole" / f).read_bytes(), f
