"""Run the validation cases and collect their metric rows."""
from __future__ import annotations

import importlib.util
import shutil
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
        spec.loader.exec_module(mod)
        out.append(CaseInfo(name, case_py.parent, mod))
    return out


def run_suite(out_dir: Path, *, full: bool = False, live: bool = False, only: list[str] | None = None,
              progress: bool = True, cases_dir: Path | None = None) -> SuiteResult:
    """Run the cases (of `cases_dir`, default validation/cases; only those named in `only` when given)."""
    res = SuiteResult(full=full, live=live)
    infos = discover(cases_dir or CASES_DIR)
    if only:
        unknown = sorted(set(only) - {i.name for i in infos})
        if unknown:
            raise SystemExit(f"unknown case(s): {', '.join(unknown)}; known: {', '.join(i.name for i in infos)}")
        infos = [i for i in infos if i.name in only]
    for info in infos:
        if info.full_only and not full and not only:
            res.skipped.append((info.name, "long study: run with --full"))
            continue
        ctx = CaseContext(name=info.name, case_dir=info.path, out_dir=out_dir / "cases" / info.name, full=full,
                          live=live)
        ctx.out_dir.mkdir(parents=True, exist_ok=True)
        if progress:
            print(f"[validate] {info.name}: {info.title} ...", flush=True)
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
            print(f"[validate] {info.name}: {status} ({len(ctx.rows)} metrics, {nfail} failed, {wall:.1f} s)",
                  flush=True)
    return res


def regenerate(cases: list[str] | None = None, codes_only: list[str] | None = None) -> None:
    """`mpmdem reference`: run the reference scenes of the cases (or of `cases`) in their REFERENCE_CODES (or in
    `codes_only`) and store them under reference_runs/ (validation/references.py)."""
    for info in discover():
        codes = getattr(info.module, "REFERENCE_CODES", ())
        if not codes or (cases and info.name not in cases):
            continue
        for variant, scene in info.module.reference_scenes(info.path).items():
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
                compress_tables(out)
                print(f"[reference]   {res.summary['wall_time_s']:.1f} s -> {out}", flush=True)
