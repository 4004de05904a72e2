"""`run_scene(..., keep_tables=False)` (what `mpmdem run` does): the tables that grow with bodies x output times
are written as the run goes and not held; the same files as a run that holds them, and the returned Result reads
them back (coupler/results.py StreamedResult)."""
import tracemalloc
from pathlib import Path

import pandas as pd
import pytest

from coupler.results import Result, StreamedResult
from coupler.run import run_scene
from coupler.scene import load_scene

CASES = Path(__file__).resolve().parents[2] / "validation" / "cases"
SCENES = {
    "dem_clusters": (CASES / "dem_wall_stack" / "wall.toml", {"time.t_end": 0.1, "output.contacts": True}),
    "mpm": (CASES / "mpm_elastic_bar" / "scene.toml", {"time.t_end": 0.01, "time.output_interval": 0.001}),
    "coupled": (CASES / "coupled_free_collision" / "scene.toml", {"time.t_end": 0.012}),
}


@pytest.mark.parametrize("kind", list(SCENES))
def test_streamed_run_writes_the_same_files_and_reads_them_back(tmp_path, kind):
    path, over = SCENES[kind]
    scene = load_scene(path, overrides=over)
    held = run_scene(scene, tmp_path / "held", progress=False)
    lean = run_scene(scene, tmp_path / "lean", progress=False, keep_tables=False)
    assert type(held) is Result and isinstance(lean, StreamedResult)
    assert not {"bodies", "contacts", "particles"} & set(lean._tables)     # nothing read back before it is used
    files = sorted(p.name for p in (tmp_path / "held").iterdir() if p.name != "summary.json")
    assert files == sorted(p.name for p in (tmp_path / "lean").iterdir() if p.name != "summary.json")
    for f in files:
        assert (tmp_path / "held" / f).read_bytes() == (tmp_path / "lean" / f).read_bytes(), f
    back = Result.read(tmp_path / "lean")
    pd.testing.assert_frame_equal(lean.bodies, back.bodies)
    pd.testing.assert_frame_equal(lean.contacts, back.contacts)
    assert len(lean.particles) == len(held.particles) == len(back.particles)
    for (t1, a), (t2, b) in zip(lean.particles, back.particles):
        assert t1 == t2
        pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(lean.energy, held.energy)
    pd.testing.assert_frame_equal(lean.mpm_bodies, held.mpm_bodies)
    assert len(lean.bodies) == len(held.bodies) and len(lean.contacts) == len(held.contacts)
    if kind != "mpm":
        assert len(lean.bodies) > 0
    if kind == "coupled":
        assert len(lean.contacts) > 0
        pd.testing.assert_frame_equal(lean.interface, held.interface)


def test_streamed_run_does_not_hold_the_rows():
    """Peak traced memory of a DEM run with many output times: the held run keeps every body row (13 doubles per
    body per output time); the streamed one only one output time's rows."""
    path, over = SCENES["dem_clusters"]
    scene = load_scene(path, overrides={**over, "time.output_interval": 0.001, "output.contacts": False})
    peaks = {}
    import tempfile
    for keep in (True, False):
        with tempfile.TemporaryDirectory() as d:
            run_scene(scene, d, progress=False, keep_tables=keep)     # compiled and warm before tracing
            tracemalloc.start()
            res = run_scene(scene, d, progress=False, keep_tables=keep)
            peaks[keep] = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            n_rows = len(res.bodies)
    assert n_rows > 500
    rows_bytes = n_rows * 13 * 8
    assert peaks[True] > rows_bytes and peaks[False] < peaks[True] - 0.8 * rows_bytes, (peaks, rows_bytes)
