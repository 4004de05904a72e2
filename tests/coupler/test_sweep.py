"""Sweeps on dask.distributed (coupler/sweep.py): a 2-worker LocalCluster gives the serial table; resumable."""
from __future__ import annotations

import pandas as pd
import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.sweep import parse_vary, plan, sweep

from tests.conftest import scene_toml

SCENE = scene_toml("""[dem]
[[dem.spheres]]
name = "a"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.002505, 0.0]
velocity = [0.0, -1.0, 0.0]
[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
""", name="sw", t_end="3e-5", dt="1e-7", output_interval="1e-5").replace('[time]', 'seed = 3\n[time]')
VARY = ["contacts[0].restitution=0.5,0.9", "dem.spheres[0].velocity=[0.0, -1.0, 0.0],[0.0, -0.5, 0.0]"]


def test_parse_and_plan():
    v = parse_vary("dem.spheres[0].velocity=[0.0, -1.0, 0.0],[1, 2, 3]")
    assert v.values == ([0.0, -1.0, 0.0], [1, 2, 3])
    assert parse_vary("mpm.shape_function=gimp,linear").values == ("gimp", "linear")
    p = plan([parse_vary("a=1,2"), parse_vary("b=x,y")], seeds=2, base_seed=5)
    assert p[:3] == [{"a": 1, "b": "x", "seed": 5}, {"a": 1, "b": "x", "seed": 6}, {"a": 1, "b": "y", "seed": 5}]
    assert len(p) == 8
    with pytest.raises(SceneError, match="--vary"):
        parse_vary("novalues")


def _stable(df: pd.DataFrame) -> pd.DataFrame:
    # what differs by how it ran: the measured time and the numba threads of the run (1 per dask worker process)
    return df.drop(columns=[c for c in df.columns if "wall_time" in c or c == "summary.threads"])


def test_two_worker_local_cluster_equals_serial_and_resumes(tmp_path, capsys):
    scene = tmp_path / "sw.toml"
    scene.write_text(SCENE)
    serial = sweep(scene, [parse_vary(v) for v in VARY], tmp_path / "serial", progress=False)
    assert len(serial) == 4 and (serial["status"] == "done").all()
    assert serial["max_fn"].nunique() == 4                   # the variants really differ
    assert list(serial["contacts[0].restitution"]) == [0.5, 0.5, 0.9, 0.9]
    par = sweep(scene, [parse_vary(v) for v in VARY], tmp_path / "par", workers=2, progress=False)
    pd.testing.assert_frame_equal(_stable(serial), _stable(par), check_exact=True)
    on_disk = pd.read_csv(tmp_path / "par" / "sweep.csv")
    assert list(on_disk["run_id"]) == list(par["run_id"])
    assert on_disk["max_fn"].tolist() == par["max_fn"].tolist()          # %.17g round-trips

    # resumable: a finished run is not redone (its row.json is reused, its folder untouched)
    first = tmp_path / "serial" / "runs" / serial["run_id"][0] / "bodies.csv"
    mtime = first.stat().st_mtime_ns
    assert main(["sweep", str(scene), "--out", str(tmp_path / "serial"), *sum((["--vary", v] for v in VARY), [])]) == 0
    out = capsys.readouterr().out
    assert "4 runs, 4 already done, 0 to run" in out
    assert first.stat().st_mtime_ns == mtime
