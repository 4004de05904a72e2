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

    def run_many(self, jobs: list, side_by_side: bool = False, catch: tuple = (), keep=None) -> list:
        """Run independent variants, [(scene or scene file, tag)] or [(scene, tag, backend)], and return their
        results in job order. Under `mpmdem validate --workers N / --scheduler ADDRESS` (self.dask) they are
        tasks of the same dask client as the cases (each worker one numba thread, coupler/sweep.py _client);
        otherwise they run one after the other in this process, as ctx.run, or with side_by_side=True as
        single-threaded processes, one per core (for runs that gain nothing from a second numba thread: DEM scenes
        below dem/solver.py PARALLEL_MIN_SPHERES run the serial kernels anyway). The runs are deterministic and
        every kernel gives the same bits on 1 and 2 threads, so the results (and the case's metric rows) are the
        same either way; only the measured wall times differ (side by side: one thread, another run on the other
        core; the case says so in its notes). catch: exception types (e.g. (SimulationError,)) a run may raise
        that are returned in its place instead of raised (the other runs go on). keep: a picklable function of
        (result, scene) (module level, or a functools.partial of one), applied where the run ran (in its
        process), whose value run_many returns instead of the result tables: an ensemble then holds what its metrics read, not every member's tables at once (with
        --full the 32 retaining-wall members' tables took ~1.1 GB), and a side-by-side run sends only that back."""
        jobs = [(self.scene(j[0]) if isinstance(j[0], str) else j[0], j[1], j[2] if len(j) > 2 else "native")
                for j in jobs]
        if not self.dask:
            workers = min(len(jobs), _cores()) if side_by_side else 1
            if workers < 2:
                return [_caught(self._run_kept, catch, scene, backend, tag, keep) for scene, tag, backend in jobs]
            return self._run_side_by_side(jobs, workers, catch, keep)
        from distributed import worker_client
        if self.progress is not None:
            self.progress(f"{len(jobs)} runs on dask: {', '.join(tag for _, tag, _ in jobs)} ...")
        with worker_client() as client:      # secedes from the worker's thread while the variants run
            futs = [client.submit(_run_variant, scene, str(self.out_dir / tag), backend, keep, pure=False,
                                  key=f"mpmdem-run-{self.name}-{tag}") for scene, tag, backend in jobs]
            out, pids = self._collect(jobs, client.gather(futs), catch)
        self.notes.append(f"{len(jobs)} runs ({', '.join(tag for _, tag, _ in jobs)}) as dask tasks in "
                          f"{len(pids)} worker process(es)")
        return out

    def _run_kept(self, scene: Scene, backend: str, tag: str, keep) -> object:
        """ctx.run, then keep(result, scene) when keep is given (run_many one after the other)."""
        res = self.run(scene, backend, tag)
        return res if keep is None else keep(res, scene)

    def _run_side_by_side(self, jobs: list, workers: int, catch: tuple, keep=None) -> list:
        """run_many's serial mode with side_by_side: `workers` spawned processes with NUMBA_NUM_THREADS=1 (the
        variable is read when a child imports numba), the results in job order; a run that raises (a type not in
        catch) raises here once the others have finished."""
        import concurrent.futures as cf
        import multiprocessing as mp
        import os
        if self.progress is not None:
            self.progress(f"{len(jobs)} runs side by side ({workers} processes, 1 numba thread each): "
                          f"{', '.join(tag for _, tag, _ in jobs)} ...")
        old = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = "1"
        try:
            with cf.ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
                futs = {pool.submit(_run_variant, scene, str(self.out_dir / tag), backend, keep): tag
                        for scene, tag, backend in jobs}
                for f in cf.as_completed(futs):
                    a = f.result()
                    if self.progress is not None and a[0] == "ok":
                        self.progress(f"run {futs[f]} done in {a[2]:.1f} s")
                out, _ = self._collect(jobs, [f.result() for f in futs], catch)
        finally:
            if old is None:
                os.environ.pop("NUMBA_NUM_THREADS", None)
            else:
                os.environ["NUMBA_NUM_THREADS"] = old
        self.notes.append(f"{len(jobs)} runs ({', '.join(tag for _, tag, _ in jobs)}) side by side: {workers} "
                          f"processes of 1 numba thread each (the wall times are of one thread with another run on "
                          f"the other core)")
        return out

    def _collect(self, jobs: list, answers: list, catch: tuple) -> tuple[list, set]:
        """_run_variant's answers from other processes, in job order -> (results, or the caught exceptions in their
        places; the process ids that ran them); records the wall times (a run that raised has none, as with
        ctx.run)."""
        out, pids = [], set()
        for (_, tag, _), a in zip(jobs, answers):
            d = _caught(_unpack, catch, a)
            if isinstance(d, Exception):
                out.append(d)
                continue
            res, self.wall_times[tag], pid = d
            out.append(res)
            pids.add(pid)
        return out, pids

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


def _caught(fn, catch: tuple, *args):
    """fn(*args), or the exception it raised when that is one of the types in catch."""
    try:
        return fn(*args)
    except catch as e:
        return e


def _cores() -> int:
    import os
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _run_variant(scene: Scene, out: str, backend: str, keep=None) -> tuple:
    """One variant of a case in another process (CaseContext.run_many: a dask worker or a side-by-side process):
    ("ok", result tables (or keep of them), wall time of the run, process id), or ("raised", exception class, its
    attributes, its text, the traceback; of the run or of keep) for _unpack to raise again (SimulationError's
    constructor takes five arguments, so the exception itself does not survive pickle's default round trip)."""
    import os
    import traceback
    from coupler.run import run_scene
    t0 = time.perf_counter()
    try:
        res = run_scene(scene, Path(out), backend=backend, progress=False)
        wall = time.perf_counter() - t0
        if keep is not None:
            res = keep(res, scene)
    except Exception as e:  # noqa: BLE001 - re-raised by _unpack in the case's process
        return "raised", type(e), dict(vars(e)), str(e), traceback.format_exc()
    return "ok", res, wall, os.getpid()


def _unpack(done: tuple) -> tuple[Result, float, int]:
    """_run_variant's answer as (result, wall time, pid); a run that raised raises the same exception type here,
    with the same attributes and text (the other process's traceback as its cause)."""
    if done[0] == "ok":
        return done[1], done[2], done[3]
    _, cls, attrs, text, tb = done
    e = cls.__new__(cls)
    e.__dict__.update(attrs)
    e.args = (text,)
    raise e from RuntimeError(f"in the run's process:\n{tb}")
