"""What a validation case sees: a context that runs scenes, records metric rows and saves one plot.

A case is a folder `validation/cases/<name>/` with its scene file(s) and a `case.py` that defines

    TITLE = "one line"
    FULL_ONLY = False          # True: only run with `mpmdem validate --full`
    def evaluate(ctx: CaseContext) -> None: ...

`evaluate` runs scenes with `ctx.run(...)`, compares with `ctx.check_rel/check_abs/check_max`, and saves a
figure with `ctx.save_plot(fig)`. Rows follow the report contract:
case, backend, metric, value, reference, tolerance, passed, wall_time_s.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from coupler.results import Result
from coupler.scene import Scene, load_scene
from validation.references import REFERENCE_DIR, ROOT, get_reference

CASES_DIR = Path(__file__).resolve().parent / "cases"
__all__ = ["MetricRow", "CaseContext", "CASES_DIR", "REFERENCE_DIR", "ROOT"]


@dataclass
class MetricRow:
    case: str
    backend: str
    metric: str
    value: float
    reference: float
    tolerance: float
    passed: bool
    wall_time_s: float
    kind: str = "rel"      # rel: |v-r|/|r| <= tol; abs: |v-r| <= tol; max: v <= tol (reference is informative)
    note: str = ""

    def as_dict(self) -> dict:
        d = asdict(self)
        for k in ("value", "reference", "tolerance", "wall_time_s"):
            v = d[k]
            d[k] = None if v is None or (isinstance(v, float) and not math.isfinite(v)) else float(v)
        return d


@dataclass
class CaseContext:
    name: str
    case_dir: Path
    out_dir: Path
    full: bool = False
    live: bool = False
    rows: list[MetricRow] = field(default_factory=list)
    plots: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    wall_times: dict[str, float] = field(default_factory=dict)
    progress: Any = None          # callable(message) for the validate progress lines (suite.py), or None
    dask: bool = False            # the case runs as a task of `validate --workers/--scheduler`: run_many submits
                                  # its variants to that same dask client (suite.run_suite_dask)

    # -- running ---------------------------------------------------------------------------------------------
    def scene(self, filename: str = "scene.toml") -> Scene:
        return load_scene(self.case_dir / filename)

    def run(self, scene: Scene | str, backend: str = "native", tag: str | None = None) -> Result:
        """Run a scene (or a scene file of this case) on a backend; the result is written under out_dir/tag."""
        from coupler.run import run_scene
        if isinstance(scene, str):
            scene = self.scene(scene)
        tag = tag or f"{scene.name}_{backend}"
        if self.progress is not None:
            self.progress(f"run {len(self.wall_times) + 1}: {tag} ({backend}) ...")
        t0 = time.perf_counter()
        res = run_scene(scene, self.out_dir / tag, backend=backend, progress=False)
        self.wall_times[tag] = time.perf_counter() - t0
        if self.progress is not None:
            self.progress(f"run {len(self.wall_times)}: {tag} done in {self.wall_times[tag]:.1f} s")
        return res

    def run_many(self, jobs: list) -> list[Result]:
        """Run independent variants, [(scene or scene file, tag)] or [(scene, tag, backend)], and return their
        results in job order. Under `mpmdem validate --workers N / --scheduler ADDRESS` (self.dask) they are
        tasks of the same dask client as the cases (each worker one numba thread, coupler/sweep.py _client);
        otherwise they run one after the other in this process, as ctx.run. The runs are deterministic, so the
        results (and the case's metric rows) are the same either way; only the measured wall times differ."""
        jobs = [(self.scene(j[0]) if isinstance(j[0], str) else j[0], j[1], j[2] if len(j) > 2 else "native")
                for j in jobs]
        if not self.dask:
            return [self.run(scene, backend, tag) for scene, tag, backend in jobs]
        from distributed import worker_client
        if self.progress is not None:
            self.progress(f"{len(jobs)} runs on dask: {', '.join(tag for _, tag, _ in jobs)} ...")
        with worker_client() as client:      # secedes from the worker's thread while the variants run
            futs = [client.submit(_run_variant, scene, str(self.out_dir / tag), backend, pure=False,
                                  key=f"mpmdem-run-{self.name}-{tag}") for scene, tag, backend in jobs]
            done = client.gather(futs)
        for (_, tag, _), (_, wall, _) in zip(jobs, done):
            self.wall_times[tag] = wall
        self.notes.append(f"{len(jobs)} runs ({', '.join(tag for _, tag, _ in jobs)}) as dask tasks in "
                          f"{len({pid for _, _, pid in done})} worker process(es)")
        return [res for res, _, _ in done]

    def reference(self, code: str, variant: str, scene: Scene | None = None) -> Result | None:
        """A reference code's result: live run with --live (and the binary present), else the stored run.

        Returns None (and notes why) when neither is available; the case then reports the comparison as missing.
        """
        res, why = get_reference(self, code, variant, scene)
        if res is None:
            self.notes.append(f"{code}/{variant}: {why}")
        return res

    # -- checks ----------------------------------------------------------------------------------------------
    def _add(self, backend, metric, value, reference, tol, passed, wall, kind, note) -> bool:
        self.rows.append(MetricRow(self.name, backend, metric, float(value), float(reference), float(tol),
                                   bool(passed), float(wall), kind, note))
        return bool(passed)

    def check_rel(self, metric: str, value: float, reference: float, rtol: float, *, backend: str = "native",
                  wall_time_s: float = float("nan"), note: str = "") -> bool:
        ok = math.isfinite(value) and abs(value - reference) <= rtol * abs(reference)
        return self._add(backend, metric, value, reference, rtol, ok, wall_time_s, "rel", note)

    def check_abs(self, metric: str, value: float, reference: float, atol: float, *, backend: str = "native",
                  wall_time_s: float = float("nan"), note: str = "") -> bool:
        ok = math.isfinite(value) and abs(value - reference) <= atol
        return self._add(backend, metric, value, reference, atol, ok, wall_time_s, "abs", note)

    def check_max(self, metric: str, value: float, limit: float, *, reference: float = float("nan"),
                  backend: str = "native", wall_time_s: float = float("nan"), note: str = "") -> bool:
        ok = math.isfinite(value) and value <= limit
        return self._add(backend, metric, value, reference, limit, ok, wall_time_s, "max", note)

    def fail(self, metric: str, why: str, *, backend: str = "native") -> bool:
        """Record a comparison that could not be made (missing reference, crash): a failure, with the reason."""
        return self._add(backend, metric, float("nan"), float("nan"), float("nan"), False, float("nan"), "missing", why)

    # -- plots -----------------------------------------------------------------------------------------------
    def save_plot(self, fig: Any, name: str | None = None) -> Path:
        import matplotlib.pyplot as plt
        self.out_dir.mkdir(parents=True, exist_ok=True)
        p = self.out_dir / f"{name or self.name}.png"
        fig.savefig(p, dpi=110, bbox_inches="tight")
        plt.close(fig)
        self.plots.append(p)
        return p


def _run_variant(scene: Scene, out: str, backend: str) -> tuple[Result, float, int]:
    """One variant of a case on a dask worker (CaseContext.run_many): its result tables, wall time and process."""
    import os
    from coupler.run import run_scene
    t0 = time.perf_counter()
    res = run_scene(scene, Path(out), backend=backend, progress=False)
    return res, time.perf_counter() - t0, os.getpid()
