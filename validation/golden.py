"""CI regression: every metric value of a quick subset of the validation cases against validation/golden.json.

The runs are deterministic (same code, same inputs -> bitwise the same numbers), so a metric value that moves by
more than the tolerance is a change of the code's results, and CI fails with a table of what moved. Intended
changes are committed with `mpmdem validate --update-golden [CASE ...]` (the commit says why).

golden.json:

    {"schema": 1,
     "rtol": 1e-9,                                  # default relative tolerance
     "tolerances": {"<case>/<backend>/<metric>": {"rtol": 1e-6, "reason": "..."}},   # looser, each with why
     "cases": {"<case>": {"<backend>": {"<metric>": value | null}}},                   # null: NaN (missing)
     "provenance": {"<case>": {"git": "<rev>", "date": "...", "python": "...", "numpy": "..."}}}

A value v passes against golden g when both are NaN, or |v - g| <= max(rtol * |g|, floor). floor is
ROUNDOFF_SHARE (1e-6) x the row's own check tolerance for rows checked against a limit or an absolute tolerance
(kind "max" / "abs"), else 1e-300 (a golden 0 of a "rel" row must stay 0). Why the floor: such a metric is often itself round-off (a native-vs-LIGGGHTS force
difference of 1.5e-10 of the peak, an interface mismatch of 2e-16), and its last bits differ between CPUs (most
likely numpy's dispatch of reductions and transcendental functions to the CPU's SIMD kernels, AVX-512 on the
second machine; not pinned down): the golden file
made on one machine moved 25 such rows by 1e-9 to 3e-3 relative on the next one, each by less than 1e-8 of its
check tolerance. A move of a millionth of a check's budget cannot change a pass/fail; any real change moves more. A metric new in the run or missing from it is a change too. Cases not run
are not compared (the golden file keeps every case; `--update-golden` rewrites only the cases it ran). When one
case/backend reports the same metric name twice, the later ones are keyed "<metric> #2", "#3", ...
"""
from __future__ import annotations

import json
import math
import platform
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable

from validation.framework import ROOT, MetricRow

GOLDEN = Path(__file__).resolve().parent / "golden.json"
DEFAULT_RTOL = 1e-9
TINY = 1e-300
ROUNDOFF_SHARE = 1e-6      # floor = this x the row's check tolerance (kinds "max" and "abs"), see above

# The quick subset run by `mpmdem regress` / CI, all against the stored reference runs (no LIGGGHTS/YADE needed).
# Measured in the baseline `make validate` (/work/baseline/reports, 2 cores, 18:54-18:56 UTC, lightly loaded): the
# nine dem_* cases together took about 1.5 min (the longest, dem_collapse_energy, ~37 s; dem_block_tip ~35 s).
# mpm_elastic_bar, mpm_self_weight, xval_impacts and xval_blocks are single small scenes (minutes at most; not yet
# timed on an idle machine: the lead should time `mpmdem regress` once and drop any case above ~3 min).
# Excluded: mpm_bui_collapse (resolution study down to h = 1.25 mm: most of the 13 min of `make validate`),
# xval_retaining_wall (~2,250 backfill spheres) and xval_column (not timed).
QUICK_CASES: tuple[str, ...] = (
    "dem_block_drop",
    "dem_block_slide",
    "dem_block_tip",
    "dem_collapse_energy",
    "dem_energy_gas",
    "dem_hertz_impact",
    "dem_mesh_roll",
    "dem_oblique_impact",
    "dem_wall_stack",
    "mpm_elastic_bar",
    "mpm_self_weight",
    "xval_impacts",
    "xval_blocks",
    "dem_rolling",                # ~5 s
    "coupled_resting_load",       # ~10 s (coupler: weight per unit depth, settlement)
    "coupled_free_collision",     # ~10 s for its three sub-step variants
    # hard cases (issue #17), times on the loaded machine (load 10-16 on 2 cores) with NUMBA_NUM_THREADS=1:
    "hard_dem",                   # ~78 s (58 s of it the 2,000-sphere settling)
    "hard_mpm",                   # ~5 s
    "hard_mpm_cell_crossing",     # ~4 s
    "hard_coupled",               # ~32 s (the ratio-1 run 11 s, the sweep)
)


@dataclass
class Change:
    case: str
    backend: str
    metric: str
    golden: float | None
    value: float | None
    rtol: float
    what: str            # "moved" | "new" | "removed"

    @property
    def rel(self) -> float:
        if self.golden is None or self.value is None:
            return math.nan
        g, v = self.golden, self.value
        if math.isnan(g) or math.isnan(v):
            return math.inf
        return abs(v - g) / max(abs(g), TINY)


def _num(v) -> float:
    return math.nan if v is None else float(v)


def _keyed(rows: Iterable[MetricRow], value) -> dict[str, dict[str, dict[str, float]]]:
    """{case: {backend: {metric: value(row)}}}; a metric name repeated within a case/backend is keyed "#2", "#3"."""
    out: dict = {}
    for r in rows:
        d = out.setdefault(r.case, {}).setdefault(r.backend, {})
        key, k = r.metric, 1
        while key in d:
            k += 1
            key = f"{r.metric} #{k}"
        d[key] = value(r)
    return out


def metric_values(rows: Iterable[MetricRow]) -> dict[str, dict[str, dict[str, float]]]:
    """{case: {backend: {metric: value}}} of metric rows (NaN for a missing comparison)."""
    return _keyed(rows, lambda r: float(r.value) if r.value is not None else math.nan)


def load(path: Path = GOLDEN) -> dict:
    if not path.exists():
        return {"schema": 1, "rtol": DEFAULT_RTOL, "tolerances": {}, "cases": {}, "provenance": {}}
    g = json.loads(path.read_text())
    if g.get("schema") != 1:
        raise ValueError(f"{path}: unknown golden schema {g.get('schema')!r}")
    return g


def tolerance(golden: dict, case: str, backend: str, metric: str) -> float:
    t = golden.get("tolerances", {}).get(f"{case}/{backend}/{metric}")
    return float(t["rtol"]) if t else float(golden.get("rtol", DEFAULT_RTOL))


def metric_floors(rows: Iterable[MetricRow]) -> dict[str, dict[str, dict[str, float]]]:
    """{case: {backend: {metric: floor}}}: ROUNDOFF_SHARE x the check tolerance of "max" / "abs" rows, else TINY."""
    def floor(r) -> float:
        tol = float(r.tolerance) if r.tolerance is not None else math.nan
        return ROUNDOFF_SHARE * abs(tol) if r.kind in ("max", "abs") and math.isfinite(tol) else TINY
    return _keyed(rows, floor)


def compare(values: dict, golden: dict, floors: dict | None = None) -> list[Change]:
    """Changes of `values` ({case: {backend: {metric: value}}}) against the golden file, for the cases in values;
    `floors` (metric_floors) are the absolute round-off floors, TINY where not given."""
    floors = floors or {}
    changes: list[Change] = []
    gcases = golden.get("cases", {})
    for case in sorted(values):
        if case not in gcases:
            for b, ms in sorted(values[case].items()):
                for m, v in ms.items():
                    changes.append(Change(case, b, m, None, v, DEFAULT_RTOL, "new"))
            continue
        run, gold = values[case], gcases[case]
        for b in sorted(set(run) | set(gold)):
            rm, gm = run.get(b, {}), gold.get(b, {})
            for m in list(gm) + [m for m in rm if m not in gm]:
                rtol = tolerance(golden, case, b, m)
                if m not in rm:
                    changes.append(Change(case, b, m, _num(gm[m]), None, rtol, "removed"))
                elif m not in gm:
                    changes.append(Change(case, b, m, None, rm[m], rtol, "new"))
                else:
                    g, v = _num(gm[m]), float(rm[m])
                    if math.isnan(g) and math.isnan(v):
                        continue
                    floor = floors.get(case, {}).get(b, {}).get(m, TINY)
                    if math.isnan(g) or math.isnan(v) or abs(v - g) > max(rtol * abs(g), floor):
                        changes.append(Change(case, b, m, g, v, rtol, "moved"))
    return changes


def format_changes(changes: list[Change]) -> str:
    """The table CI prints: one line per changed metric."""
    if not changes:
        return "golden: no metric moved"

    def f(x):
        return "–" if x is None else f"{x:.12g}"
    head = ("case", "backend", "metric", "golden", "now", "rel. change", "rtol", "what")
    body = [(c.case, c.backend, c.metric, f(c.golden), f(c.value),
             "–" if math.isnan(c.rel) else f"{c.rel:.3g}", f"{c.rtol:g}", c.what) for c in changes]
    w = [max(len(str(r[k])) for r in [head] + body) for k in range(len(head))]
    lines = ["  ".join(str(x).ljust(w[k]) for k, x in enumerate(r)) for r in [head] + body]
    lines.insert(1, "  ".join("-" * n for n in w))
    return f"golden: {len(changes)} metric(s) changed (validation/golden.json)\n" + "\n".join(lines)


def git_revision(root: Path = ROOT) -> str:
    try:
        rev = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return (rev or "unknown") + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def update(values: dict, path: Path = GOLDEN) -> dict:
    """Rewrite the entries of the cases in `values` (others are kept, tolerances kept); returns the new file."""
    import numpy as np
    g = load(path)
    stamp = {"git": git_revision(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
             "python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine()}
    for case, backends in values.items():
        g["cases"][case] = {b: {m: (None if math.isnan(v) else float(v)) for m, v in ms.items()}
                            for b, ms in sorted(backends.items())}
        g.setdefault("provenance", {})[case] = stamp
    g["cases"] = dict(sorted(g["cases"].items()))
    g["provenance"] = dict(sorted(g.get("provenance", {}).items()))
    path.write_text(json.dumps(g, indent=1, allow_nan=False) + "\n")   # repr round-trips every float exactly
    return g


def rows_from_summary(path: Path) -> list[MetricRow]:
    """The metric rows of a written report (reports/summary.json), to seed or check golden values without a rerun."""
    return rows_from_dicts(json.loads(Path(path).read_text()))


def rows_from_dicts(dicts: Iterable[dict]) -> list[MetricRow]:
    """MetricRows from their as_dict() form (summary.json rows, suite records of distributed runs)."""
    out = []
    for d in dicts:
        out.append(MetricRow(d["case"], d["backend"], d["metric"], _num(d["value"]), _num(d["reference"]),
                             _num(d["tolerance"]), bool(d["passed"]), _num(d["wall_time_s"]), d.get("kind", "rel"),
                             d.get("note", "")))
    return out


def check(rows: Iterable[MetricRow], path: Path = GOLDEN) -> tuple[bool, str]:
    """(no change, table) of the metric rows of a run against the golden file."""
    rows = list(rows)
    changes = compare(metric_values(rows), load(path), metric_floors(rows))
    return not changes, format_changes(changes)
