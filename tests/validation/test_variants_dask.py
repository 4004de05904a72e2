"""`mpmdem validate --workers N`: the variants inside a case (CaseContext.run_many) go through the same dask client
as the cases; serial and a 2-worker LocalCluster give identical metric rows (issue 19). run_many(side_by_side=True)
in the serial mode (spawned single-threaded processes, one per core): the same rows again, and a run that raises
comes back in its slot when its type is caught, raises otherwise; with keep, each run's process returns only
keep(result)."""
from __future__ import annotations

import pickle
import textwrap

import pytest

from coupler.errors import SimulationError
from coupler.scene import load_scene, loads_scene
from tests.coupler.test_sweep import SCENE
from validation.framework import CaseContext, _cores
from validation.suite import discover, run_suite, run_suite_dask, suite_record

# three restitutions of the sphere drop of tests/coupler/test_sweep.py (its scene file, written into the case)
CASE = textwrap.dedent('''
    """Three independent variants through ctx.run_many."""
    from coupler.scene import load_scene

    TITLE = "variants through run_many"
    SIDE_BY_SIDE = False


    def evaluate(ctx):
        es = (0.5, 0.7, 0.9)
        runs = ctx.run_many([(load_scene(ctx.case_dir / "scene.toml", overrides={"contacts[0].restitution": e},
                                         name=f"v{e}"), f"e{e}") for e in es], side_by_side=SIDE_BY_SIDE)
        for e, res in zip(es, runs):
            b = res.body("a")
            ctx.check_max(f"vy_end_e{e}", float(b.vy.iloc[-1]), 10.0, reference=float(b.vy.iloc[0]))
            ctx.check_abs(f"max_fn_e{e}", float(res.contacts.fn.max()), 0.0, 1e9)
''')


# the same variants with keep: each run's process (dask worker, or this one) returns _end_state(result) only
KEPT = textwrap.dedent('''
    """The variants through ctx.run_many with keep."""
    from coupler.scene import load_scene
    from tests.validation.test_variants_dask import _end_state

    TITLE = "variants through run_many, kept"


    def evaluate(ctx):
        es = (0.5, 0.7, 0.9)
        kept = ctx.run_many([(load_scene(ctx.case_dir / "scene.toml", overrides={"contacts[0].restitution": e},
                                         name=f"v{e}"), f"e{e}") for e in es], keep=_end_state)
        for e, (y, vy, n, name) in zip(es, kept):
            ctx.check_max(f"vy_end_e{e}", vy, 10.0, reference=0.0)
            ctx.check_abs(f"outputs_e{e}", float(n), 0.0, 1e9)
            ctx.check_abs(f"keep_got_its_scene_e{e}", float(name == f"v{e}"), 1.0, 0.0)
''')


def _rows(rec: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "wall_time_s"} for c in rec["cases"] for r in c["rows"]]


def test_case_variants_on_a_two_worker_cluster_equal_serial(tmp_path):
    cases = tmp_path / "cases"
    (cases / "variants").mkdir(parents=True)
    (cases / "variants" / "case.py").write_text(CASE)
    (cases / "variants" / "scene.toml").write_text(SCENE)
    (cases / "variants_kept").mkdir()
    (cases / "variants_kept" / "case.py").write_text(KEPT)
    (cases / "variants_kept" / "scene.toml").write_text(SCENE)
    serial = suite_record(run_suite(tmp_path / "serial", cases_dir=cases, progress=False), tmp_path / "serial")
    par = run_suite_dask(tmp_path / "par", cases_dir=cases, workers=2, progress=False)
    rows = _rows(serial)
    assert len(rows) == 15 and all(r["passed"] for r in rows), [c["error"] for c in serial["cases"]]
    assert len({r["value"] for r in rows if r["metric"].startswith("vy_end")}) == 3     # the variants differ
    assert _rows(par) == rows                                                            # bit for bit
    kept = {r["metric"]: r["value"] for r in rows if r["case"] == "variants_kept"}
    assert all(kept[f"vy_end_e{e}"] == r["value"] for e in (0.5, 0.7, 0.9)              # keep's value = the tables'
               for r in rows if r["case"] == "variants" and r["metric"] == f"vy_end_e{e}")
    for c in (0, 1):
        assert not any("dask tasks" in n for n in serial["cases"][c]["notes"])
        assert any("3 runs (e0.5, e0.7, e0.9) as dask tasks" in n for n in par["cases"][c]["notes"])
    for d in ("serial", "par"):
        assert (tmp_path / d / "cases" / "variants" / "e0.7" / "bodies.csv").exists()


@pytest.mark.skipif(_cores() < 2, reason="side by side needs at least 2 cores (this process may use 1)")
def test_side_by_side_variants_equal_serial_and_errors_come_back(tmp_path):
    cases = tmp_path / "cases"
    for name, flag in (("serial", "False"), ("side", "True")):
        (cases / name).mkdir(parents=True)
        (cases / name / "case.py").write_text(CASE.replace("SIDE_BY_SIDE = False", f"SIDE_BY_SIDE = {flag}"))
        (cases / name / "scene.toml").write_text(SCENE)
    rec = suite_record(run_suite(tmp_path / "out", cases_dir=cases, progress=False), tmp_path / "out")
    by = {c["name"]: c for c in rec["cases"]}
    strip = [[{k: v for k, v in r.items() if k not in ("wall_time_s", "case")} for r in by[n]["rows"]]
             for n in ("serial", "side")]
    assert len(strip[0]) == 6 and strip[0] == strip[1], by["side"]["error"]                  # bit for bit
    assert any("3 runs (e0.5, e0.7, e0.9) side by side: 2 processes" in n for n in by["side"]["notes"])
    assert not any("side by side" in n for n in by["serial"]["notes"])
    # a run that stops: its SimulationError (step, body, quantity kept) in its slot, the other run's result beside it
    ctx = CaseContext("side", cases / "side", tmp_path / "err")
    good = load_scene(cases / "side" / "scene.toml", name="good")
    bad = loads_scene(SCENE.replace("[dem]", "[domain]\nmin = [-0.001, -0.01, -0.01]\nmax = [0.001, 0.01, 0.01]\n[dem]")
                      .replace("velocity = [0.0, -1.0, 0.0]", "velocity = [50.0, -1.0, 0.0]"), name="bad")
    out = ctx.run_many([(good, "good"), (bad, "bad")], side_by_side=True, catch=(SimulationError,))
    assert not isinstance(out[0], Exception) and len(out[0].body("a")) > 1 and "good" in ctx.wall_times
    assert isinstance(out[1], SimulationError) and out[1].body and out[1].quantity and "bad" not in ctx.wall_times
    with pytest.raises(SimulationError) as e:
        ctx.run_many([(good, "good2"), (bad, "bad2")], side_by_side=True)
    assert str(e.value) == str(out[1]) and e.value.step == out[1].step


def _end_state(res, scene):
    """run_many's keep in the tests here: module level, so that a spawned process can unpickle it; the scene's
    name shows that keep gets the scene its run ran."""
    b = res.body("a")
    return float(b.y.iloc[-1]), float(b.vy.iloc[-1]), len(b), scene.name


@pytest.mark.skipif(_cores() < 2, reason="side by side needs at least 2 cores (this process may use 1)")
def test_keep_returns_what_the_function_reads_where_the_run_ran(tmp_path):
    (tmp_path / "case").mkdir()
    (tmp_path / "case" / "scene.toml").write_text(SCENE)
    jobs = [(load_scene(tmp_path / "case" / "scene.toml", overrides={"contacts[0].restitution": e}, name=f"v{e}"),
             f"e{e}") for e in (0.5, 0.9)]
    whole = CaseContext("case", tmp_path / "case", tmp_path / "whole").run_many(jobs)
    want = [_end_state(r, sc) for r, (sc, _) in zip(whole, jobs)]
    assert want[0] != want[1]                                    # the variants differ
    for side in (False, True):
        ctx = CaseContext("case", tmp_path / "case", tmp_path / f"keep{side}")
        got = ctx.run_many(jobs, side_by_side=side, keep=_end_state)
        assert got == want and set(ctx.wall_times) == {"e0.5", "e0.9"}              # bit for bit, timed alike
        assert (tmp_path / f"keep{side}" / "e0.9" / "bodies.csv").exists()           # the tables still written


def test_a_case_function_pickles_by_name_for_keep():
    """discover registers each case module under its name, so a case's keep function (xval_retaining_wall's
    member_histories) pickles by reference and a run's process finds it by importing the case."""
    mod = next(i.module for i in discover() if i.name == "xval_retaining_wall")
    assert pickle.loads(pickle.dumps(mod.member_histories)) is mod.member_histories
