"""Run the validation cases and collect their metric rows."""
from __future__ import annotations

import importlib.util
import shutil
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

from coupler.errors import UnsupportedFeature
from validation.framework import CASES_DIR, CaseContext, MetricRow
from validation.references import compress_tables, run_reference, stored_dir


@dataclass
class CaseInfo:
    name: str
    path: Path
    module: ModuleType

    @property
    def title(self) -> str:
        return getattr(self.module, "TITLE", self.name)

    @property
    def full_only(self) -> bool:
        return bool(getattr(self.module, "FULL_ONLY", False))


@dataclass
class CaseReport:
    info: CaseInfo
    ctx: CaseContext
    wall_time_s: float
    error: str = ""

    @property
    def passed(self) -> bool:
        return not self.error and bool(self.ctx.rows) and all(r.passed for r in self.ctx.rows)


@dataclass
class SuiteResult:
    cases: list[CaseReport] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    full: bool = False
    live: bool = False

    @property
    def rows(self) -> list[MetricRow]:
        return [r for c in self.cases for r in c.ctx.rows]

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.cases)


def discover(cases_dir: Path = CASES_DIR) -> list[CaseInfo]:
    out = []
    for case_py in sorted(cases_dir.glob("*/case.py")):
        name = case_py.parent.name
        spec = importlib.util.spec_from_file_location(f"validation.cases.{name}.case", case_py)
        mod = importlib.util.module_from_spec(spec)
        # registered under its name (importlib's recipe), so that pickle finds a case's functions by that name:
        # run_many(keep=fn) sends fn to the run's process, which imports the case module there
        sys.modules[spec.name] = mod
        spec.loader.exec_module(mod)
        out.append(CaseInfo(name, case_py.parent, mod))
    return out


def run_suite(out_dir: Path, *, full: bool = False, live: bool = False, only: list[str] | None = None,
              progress: bool = True, cases_dir: Path | None = None, dask: bool = False) -> SuiteResult:
    """Run the cases (of `cases_dir`, default validation/cases; only those named in `only` when given). dask: the
    cases run as tasks of a dask client (run_suite_dask), their variants then too (CaseContext.run_many)."""
    res = SuiteResult(full=full, live=live)
    infos = discover(cases_dir) if cases_dir else discover()
    if only:
        unknown = sorted(set(only) - {i.name for i in infos})
        if unknown:
            raise SystemExit(f"unknown case(s): {', '.join(unknown)}; known: {', '.join(i.name for i in infos)}")
        infos = [i for i in infos if i.name in only]
    def long_study(i) -> bool:           # skipped unless --full (or named)
        return i.full_only and not full and not only
    todo = [i for i in infos if not long_study(i)]
    t_suite = time.perf_counter()
    for info in infos:
        if long_study(info):
            res.skipped.append((info.name, "long study: run with --full"))
            continue
        ctx = CaseContext(name=info.name, case_dir=info.path, out_dir=out_dir / "cases" / info.name, full=full,
                          live=live, dask=dask)
        ctx.out_dir.mkdir(parents=True, exist_ok=True)
        k = len(res.cases) + 1
        if progress:   # which case, how far in the suite, and each run of the case as it starts and ends
            print(f"[validate {k}/{len(todo)}] {info.name}: {info.title} ... "
                  f"(suite {time.perf_counter() - t_suite:.0f} s)", flush=True)
            t_case = time.perf_counter()
            ctx.progress = lambda msg, name=info.name, t_case=t_case, k=k: print(
                f"[validate {k}/{len(todo)}]   {name}: {msg} (case {time.perf_counter() - t_case:.0f} s)",
                flush=True)
        t0 = time.perf_counter()
        err = ""
        try:
            info.module.evaluate(ctx)
        except Exception as e:  # a crashing case is a failed case, reported with its reason
            err = f"{type(e).__name__}: {e}"
            (ctx.out_dir / "error.txt").write_text(traceback.format_exc())
            ctx.fail("case", err)
        wall = time.perf_counter() - t0
        rep = CaseReport(info, ctx, wall, err)
        res.cases.append(rep)
        if progress:
            status = "PASS" if rep.passed else "FAIL"
            nfail = sum(not r.passed for r in ctx.rows)
            print(f"[validate {k}/{len(todo)}] {info.name}: {status} ({len(ctx.rows)} metrics, {nfail} failed, "
                  f"{wall:.1f} s)", flush=True)
    return res


def case_record(rep: CaseReport, out_dir: Path) -> dict:
    """A case's report as plain data (what the HTML report and the golden check need; crosses process borders)."""
    import os
    return {"name": rep.info.name, "title": rep.info.title, "doc": (rep.info.module.__doc__ or "").strip(),
            "error": rep.error, "wall_time_s": rep.wall_time_s, "rows": [r.as_dict() for r in rep.ctx.rows],
            "plots": [os.path.relpath(p, out_dir) for p in rep.ctx.plots], "notes": list(rep.ctx.notes)}


def suite_record(res: SuiteResult, out_dir: Path) -> dict:
    """A suite result as plain data (suite.json without the provenance the report adds)."""
    return {"full": res.full, "live": res.live, "skipped": [list(s) for s in res.skipped],
            "cases": [case_record(c, out_dir) for c in res.cases]}


def _case_task(out_dir: str, name: str, full: bool, live: bool, cases_dir: str | None) -> dict:
    """One case on a dask worker: the same run_suite path as serial (its variants submitted to the same client),
    returned as plain data."""
    res = run_suite(Path(out_dir), full=full, live=live, only=[name], progress=False,
                    cases_dir=Path(cases_dir) if cases_dir else None, dask=True)
    return case_record(res.cases[0], Path(out_dir))


def run_suite_dask(out_dir: Path, *, full: bool = False, live: bool = False, only: list[str] | None = None,
                   workers: int | None = None, scheduler: str | None = None, cases_dir: Path | None = None,
                   progress: bool = True) -> dict:
    """run_suite with each case a dask.distributed task (LocalCluster of `workers` processes, or the cluster at
    `scheduler`); returns the suite record (report.suite_record layout without provenance), cases in suite order.
    Every case is deterministic, so the rows equal a serial run's (only the measured wall times differ)."""
    from coupler.sweep import _client
    from distributed import as_completed
    infos = discover(cases_dir or CASES_DIR)
    if only:
        unknown = sorted(set(only) - {i.name for i in infos})
        if unknown:
            raise SystemExit(f"unknown case(s): {', '.join(unknown)}; known: {', '.join(i.name for i in infos)}")
        infos = [i for i in infos if i.name in only]
    skipped = [(i.name, "long study: run with --full") for i in infos if i.full_only and not full and not only]
    infos = [i for i in infos if not (i.full_only and not full and not only)]
    client, cluster = _client(workers, scheduler)
    recs: dict[str, dict] = {}
    try:
        futs = {client.submit(_case_task, str(out_dir), i.name, full, live, str(cases_dir) if cases_dir else None,
                              key=f"mpmdem-case-{i.name}", pure=False): i.name for i in infos}
        for fut in as_completed(futs):
            r = fut.result()
            recs[r["name"]] = r
            if progress:
                nfail = sum(not x["passed"] for x in r["rows"])
                ok = not r["error"] and r["rows"] and nfail == 0
                print(f"[validate] {r['name']}: {'PASS' if ok else 'FAIL'} ({len(r['rows'])} metrics, {nfail} failed, "
                      f"{r['wall_time_s']:.1f} s)", flush=True)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return {"full": full, "live": live, "skipped": [list(x) for x in skipped],
            "cases": [recs[i.name] for i in infos]}


def regenerate(cases: list[str] | None = None, codes_only: list[str] | None = None,
               variants_only: list[str] | None = None) -> None:
    """`mpmdem reference`: run the reference scenes of the cases (or of `cases`) in their REFERENCE_CODES (or in
    `codes_only`; only the variants in `variants_only` when given) and store them under reference_runs/
    (validation/references.py). A case with a `regenerate_reference()` (its own fine native runs, e.g. the converged
    surface of mpm_bui_implicit) reruns those too, as the code "native"."""
    for info in discover():
        own = getattr(info.module, "regenerate_reference", None)     # a case's stored fine native runs (code "native")
        if own is not None and not (cases and info.name not in cases) and (not codes_only or "native" in codes_only):
            print(f"[reference] {info.name} native ...", flush=True)
            for path in own():
                print(f"[reference]   -> {path}", flush=True)
        codes = getattr(info.module, "REFERENCE_CODES", ())
        if not codes or (cases and info.name not in cases):
            continue
        for variant, scene in info.module.reference_scenes(info.path).items():
            if variants_only and variant not in variants_only:
                continue
            for code in codes:
                if codes_only and code not in codes_only:
                    continue
                out = stored_dir(info.name, code, variant)
                if out.exists():
                    shutil.rmtree(out)
                print(f"[reference] {info.name} {code} {variant} ...", flush=True)
                try:
                    res = run_reference(code, scene, out)
                except UnsupportedFeature as e:
                    print(f"[reference]   not expressible, not stored: {e}", flush=True)
                    shutil.rmtree(out, ignore_errors=True)
                    continue
                trim = getattr(info.module, "trim_reference", None)     # a case may keep only the rows it reads
                if trim is not None:
                    trim(out)
                compress_tables(out)
                print(f"[reference]   {res.summary['wall_time_s']:.1f} s -> {out}", flush=True)
