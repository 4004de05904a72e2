"""`mpmdem validate --workers N`: the variants inside a case (CaseContext.run_many) go through the same dask client
as the cases; serial and a 2-worker LocalCluster give identical metric rows (issue 19)."""
from __future__ import annotations

import textwrap

from tests.coupler.test_sweep import SCENE
from validation.suite import run_suite, run_suite_dask, suite_record

# three restitutions of the sphere drop of tests/coupler/test_sweep.py (its scene file, written into the case)
CASE = textwrap.dedent('''
    """Three independent variants through ctx.run_many."""
    from coupler.scene import load_scene

    TITLE = "variants through run_many"


    def evaluate(ctx):
        es = (0.5, 0.7, 0.9)
        runs = ctx.run_many([(load_scene(ctx.case_dir / "scene.toml", overrides={"contacts[0].restitution": e},
                                         name=f"v{e}"), f"e{e}") for e in es])
        for e, res in zip(es, runs):
            b = res.body("a")
            ctx.check_max(f"vy_end_e{e}", float(b.vy.iloc[-1]), 10.0, reference=float(b.vy.iloc[0]))
            ctx.check_abs(f"max_fn_e{e}", float(res.contacts.fn.max()), 0.0, 1e9)
''')


def _rows(rec: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "wall_time_s"} for c in rec["cases"] for r in c["rows"]]


def test_case_variants_on_a_two_worker_cluster_equal_serial(tmp_path):
    cases = tmp_path / "cases"
    (cases / "variants").mkdir(parents=True)
    (cases / "variants" / "case.py").write_text(CASE)
    (cases / "variants" / "scene.toml").write_text(SCENE)
    serial = suite_record(run_suite(tmp_path / "serial", cases_dir=cases, progress=False), tmp_path / "serial")
    par = run_suite_dask(tmp_path / "par", cases_dir=cases, workers=2, progress=False)
    rows = _rows(serial)
    assert len(rows) == 6 and all(r["passed"] for r in rows), serial["cases"][0]["error"]
    assert len({r["value"] for r in rows if r["metric"].startswith("vy_end")}) == 3     # the variants differ
    assert _rows(par) == rows                                                            # bit for bit
    assert not any("dask tasks" in n for n in serial["cases"][0]["notes"])
    assert any("3 runs (e0.5, e0.7, e0.9) as dask tasks" in n for n in par["cases"][0]["notes"])
    for d in ("serial", "par"):
        assert (tmp_path / d / "cases" / "variants" / "e0.7" / "bodies.csv").exists()
