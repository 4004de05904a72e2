"""CI regression against validation/golden.json (validation/golden.py): a tiny fake case through the real CLI."""
from __future__ import annotations

import json
import math

import pytest

from coupler.cli import main
from validation import golden
from validation.framework import MetricRow

FAKE_CASE = '''
"""A fake case: its numbers come from value.json next to it (so a test can change them)."""
import json
TITLE = "fake"
def evaluate(ctx):
    v = json.loads((ctx.case_dir / "value.json").read_text())
    ctx.check_rel("peak force [N]", v["a"], 1.0, 0.5)
    ctx.check_rel("peak force [N]", v["b"], 2.0, 0.5)          # same name twice: keyed "peak force [N] #2"
    ctx.check_abs("zero", v["zero"], 0.0, 1.0, backend="yade")
    if "extra" in v:
        ctx.check_max("extra", v["extra"], 10.0)
'''


def _cases(tmp_path, **values):
    d = tmp_path / "cases" / "fake_case"
    d.mkdir(parents=True, exist_ok=True)
    (d / "case.py").write_text(FAKE_CASE)
    (d / "value.json").write_text(json.dumps(values))
    return tmp_path / "cases"


def _cli(tmp_path, cases, *extra):
    return main(["validate", "--out", str(tmp_path / "rep"), "--cases-dir", str(cases),
                 "--golden", str(tmp_path / "golden.json"), *extra])


def test_update_then_regress_passes_and_a_moved_number_fails_with_a_table(tmp_path, capsys):
    cases = _cases(tmp_path, a=1.0 / 3.0, b=2.0, zero=0.0)
    assert _cli(tmp_path, cases, "--update-golden") == 0
    g = json.loads((tmp_path / "golden.json").read_text())
    assert g["cases"]["fake_case"] == {"native": {"peak force [N]": 1.0 / 3.0, "peak force [N] #2": 2.0},
                                       "yade": {"zero": 0.0}}
    assert g["cases"]["fake_case"]["native"]["peak force [N]"] == 1.0 / 3.0       # exact round trip
    assert "git" in g["provenance"]["fake_case"]
    capsys.readouterr()
    assert _cli(tmp_path, cases, "--regress") == 0
    assert "no metric moved" in capsys.readouterr().out

    # a change inside 1e-9 relative passes; a larger one fails and is tabled
    _cases(tmp_path, a=1.0 / 3.0 * (1 + 5e-10), b=2.0, zero=0.0)
    assert _cli(tmp_path, cases, "--regress") == 0
    _cases(tmp_path, a=1.0 / 3.0 * (1 + 2e-9), b=2.0, zero=1e-5, extra=1.0)   # zero: abs row, floor 1e-6 x 1.0
    capsys.readouterr()
    assert _cli(tmp_path, cases, "--regress") == 5
    out = capsys.readouterr().out
    assert "3 metric(s) changed" in out
    lines = {ln.split("  ")[0] + "|" + ln for ln in out.splitlines() if ln.startswith("fake_case")}
    assert any("peak force [N] " in ln and "moved" in ln and "2e-09" in ln for ln in lines), out
    assert any("zero" in ln and "moved" in ln for ln in lines), out          # 0 stays 0 within its floor
    assert any("extra" in ln and "new" in ln for ln in lines), out
    # the regress subcommand is the same path
    assert main(["regress", "--out", str(tmp_path / "rep2"), "--cases-dir", str(cases),
                 "--golden", str(tmp_path / "golden.json")]) == 5


def test_compare_rules():
    rows = [MetricRow("c", "native", "m", 1.0, 1.0, 0.1, True, math.nan),
            MetricRow("c", "native", "missing", math.nan, math.nan, math.nan, False, math.nan, "missing", "why")]
    g = {"schema": 1, "rtol": 1e-9, "cases": {"c": {"native": {"m": 1.0 + 1e-6, "missing": None, "gone": 3.0}},
                                              "not_run": {"native": {"x": 1.0}}},
         "tolerances": {"c/native/m": {"rtol": 1e-5, "reason": "test: a stated looser tolerance"}}}
    ch = golden.compare(golden.metric_values(rows), g)
    assert [(c.metric, c.what) for c in ch] == [("gone", "removed")]     # NaN == NaN; looser rtol; not_run skipped
    g["tolerances"] = {}
    ch = golden.compare(golden.metric_values(rows), g)
    assert sorted((c.metric, c.what) for c in ch) == [("gone", "removed"), ("m", "moved")]
    assert "rel. change" in golden.format_changes(ch)


def test_roundoff_floor_is_a_millionth_of_the_check_tolerance():
    """A "max" / "abs" row may move by ROUNDOFF_SHARE x its check tolerance (round-off metrics differ between CPUs);
    beyond that, and for "rel" rows, the relative rtol rules."""
    rows = [MetricRow("c", "native", "diff", 1.5e-10, math.nan, 0.01, True, math.nan, "max"),
            MetricRow("c", "native", "force", 2.0, 2.0, 0.01, True, math.nan, "rel")]
    g = {"schema": 1, "rtol": 1e-9, "cases": {"c": {"native": {"diff": 1.5e-10 + 0.9e-8, "force": 2.0 + 1e-12}}}}
    floors = golden.metric_floors(rows)
    assert floors["c"]["native"]["diff"] == pytest.approx(1e-8)
    assert golden.compare(golden.metric_values(rows), g, floors) == []                # 0.9e-8 < 1e-8 floor
    g["cases"]["c"]["native"]["diff"] = 1.5e-10 + 1.1e-8
    g["cases"]["c"]["native"]["force"] = 2.0 + 1e-8                                   # rel row: 5e-9 > 1e-9
    ch = golden.compare(golden.metric_values(rows), g, floors)
    assert sorted(c.metric for c in ch) == ["diff", "force"]
    assert golden.compare(golden.metric_values(rows), g) != []                      # no floors: rtol only


def test_committed_golden_file_is_well_formed():
    g = golden.load()
    assert g["schema"] == 1 and g["rtol"] == 1e-9
    for key, t in g.get("tolerances", {}).items():
        assert t.get("reason"), f"looser tolerance {key} must say why"
    from validation.framework import CASES_DIR
    known = {p.parent.name for p in CASES_DIR.glob("*/case.py")}
    assert set(golden.QUICK_CASES) <= known
    assert set(g["cases"]) <= known, "golden values of a case that no longer exists"
    for case, backends in g["cases"].items():
        assert case in g["provenance"]
        for b, ms in backends.items():
            assert all(v is None or isinstance(v, float) for v in ms.values()), (case, b)
    # cases of the quick subset still without golden values make `mpmdem regress` fail ("new") until the lead
    # runs `mpmdem validate --update-golden` on the merged tree


def test_validate_on_two_dask_workers_equals_serial(tmp_path):
    """`validate --workers 2` runs each case as a dask task: same rows as serial (wall times aside)."""
    cases = _cases(tmp_path, a=1.0 / 3.0, b=2.0, zero=0.0)
    other = tmp_path / "cases" / "other_case"
    other.mkdir()
    (other / "case.py").write_text(FAKE_CASE)
    (other / "value.json").write_text(json.dumps({"a": 0.7, "b": 0.1, "zero": 0.0, "extra": 3.0}))
    assert _cli(tmp_path, cases, "--update-golden") == 0
    assert main(["validate", "--out", str(tmp_path / "dask"), "--cases-dir", str(cases), "--workers", "2",
                 "--golden", str(tmp_path / "golden.json"), "--regress"]) == 0

    def rows(d):
        rec = json.loads((d / "suite.json").read_text())
        return [(c["name"], [{k: v for k, v in r.items() if k != "wall_time_s"} for r in c["rows"]])
                for c in rec["cases"]]
    assert rows(tmp_path / "dask") == rows(tmp_path / "rep")
