"""The user-facing pipeline: validate -> report files with the contract keys; bench on a tiny lattice."""
import json

from coupler.bench import bench_lattice_native
from validation.report import write_report
from validation.suite import discover, run_suite


def test_every_case_declares_title_and_evaluate():
    infos = discover()
    assert {"dem_hertz_impact", "dem_oblique_impact", "dem_energy_gas"} <= {i.name for i in infos}
    for i in infos:
        assert callable(getattr(i.module, "evaluate", None)), i.name
        assert isinstance(getattr(i.module, "TITLE", None), str), i.name


def test_validate_writes_report_with_contract_keys(tmp_path):
    res = run_suite(tmp_path, only=["dem_oblique_impact"], progress=False)
    index = write_report(res, tmp_path)
    rows = json.loads((tmp_path / "summary.json").read_text())
    assert rows and index.exists()
    for r in rows:
        assert {"case", "backend", "metric", "value", "reference", "tolerance", "passed", "wall_time_s"} <= set(r)
    assert all(r["passed"] for r in rows), rows
    assert "<img" in index.read_text()


def test_failing_case_is_reported_as_failure(tmp_path, monkeypatch):
    """A crashing case must show up as a failed row with the reason, never be dropped."""
    infos = [i for i in discover() if i.name == "dem_oblique_impact"]

    def boom(ctx):
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(infos[0].module, "evaluate", boom)
    monkeypatch.setattr("validation.suite.discover", lambda: infos)
    res = run_suite(tmp_path, progress=False)
    assert not res.passed
    assert res.rows[0].kind == "missing" and "solver exploded" in res.rows[0].note


def test_bench_runs_on_a_tiny_lattice():
    r = bench_lattice_native(1, nx=4, ny=4, nz=4, steps=20)
    assert r["particles"] == 64 and r["particle_steps_per_s"] > 0 and r["bytes_per_sphere"] < 200
