"""Parameter sweeps and seed ensembles of one scene file, run through dask.distributed.

    mpmdem sweep SCENE.toml --vary FIELD=V1,V2,... [--vary ...] [--seeds N] [--backend B]
                 [--metric NAME ...] [--workers N | --scheduler ADDRESS] --out DIR

FIELD is a dotted path into the scene file as `coupler.scene.load_scene(overrides=...)` takes it
("contacts[0].restitution", "dem.spheres[0].velocity", "time.dt"); each value is a TOML literal (0.5, "gimp",
[0.0, -2.0, 0.0]; a bare word is a string). The runs are the Cartesian product of the --vary lists, times
`seed = base, base+1, ..., base+N-1` with --seeds N (base = the scene's seed), in that order.

Each run writes its result tables to DIR/runs/<run id>/ (run id: hash of scene text, overrides and backend) and,
when it finished, DIR/runs/<run id>/row.json. A rerun of the same sweep reuses every row.json (finished runs are
not redone); failed runs are recorded with their one-line reason and redone next time. The table of all runs is
DIR/sweep.csv (and DIR/sweep.parquet when pyarrow is installed), one row per run in product order: the varied
values, seed, backend, run_id, status, the scalar summary keys (steps, dt, particles, wall_time_s, ...) and the
chosen metrics (METRICS below, default: energy_final, max_fn).

Scheduling: in-process by default (a dask.distributed Client with one in-process worker thread), a LocalCluster of
N single-threaded worker processes with --workers N, an existing cluster with --scheduler ADDRESS (its workers
must see the scene file and DIR at the same paths, i.e. a shared file system). Every run is deterministic, so the
table is the same whichever way it ran, except the measured wall_time_s column and summary.threads (the numba
threads each run had: one per worker process with --workers, the machine's cores in-process).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from coupler.errors import SceneError

__all__ = ["Vary", "parse_vary", "plan", "sweep", "METRICS", "run_one"]


@dataclass(frozen=True)
class Vary:
    field: str
    values: tuple


def _split_top(text: str) -> list[str]:
    """Split on commas that are not inside brackets or quotes."""
    out, depth, cur, quote = [], 0, [], None
    for ch in text:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    out.append("".join(cur).strip())
    return out


def _literal(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text          # a bare word: a string ("gimp")


def parse_vary(spec: str) -> Vary:
    """'contacts[0].restitution=0.5,0.8' -> Vary('contacts[0].restitution', (0.5, 0.8))."""
    if "=" not in spec:
        raise SceneError("--vary", f"must be FIELD=V1,V2,... got {spec!r}")
    name, vals = spec.split("=", 1)
    name = name.strip()
    values = tuple(_literal(v) for v in _split_top(vals) if v != "")
    if not name or not values:
        raise SceneError("--vary", f"must be FIELD=V1,V2,... with at least one value, got {spec!r}")
    return Vary(name, values)


def plan(varies: list[Vary], seeds: int | None = None, base_seed: int = 0) -> list[dict[str, Any]]:
    """The overrides of every run, in product order (the first --vary slowest, seeds fastest)."""
    names = [v.field for v in varies]
    if len(set(names)) != len(names):
        raise SceneError("--vary", f"a field is varied twice: {names}")
    if seeds is not None and seeds < 1:
        raise SceneError("--seeds", f"must be >= 1, got {seeds}")
    axes = [v.values for v in varies]
    if seeds is not None:
        if "seed" in names:
            raise SceneError("--seeds", "cannot be combined with --vary seed=...")
        names.append("seed")
        axes.append(tuple(base_seed + k for k in range(seeds)))
    return [dict(zip(names, combo)) for combo in itertools.product(*axes)]


# -- metrics of a result (name -> function of the Result returning a float or a {column: float} dict) --------------
def _energy_final(res) -> dict:
    e = res.energy
    if not len(e):
        return {}
    last = e.sort_values("t").iloc[-1]
    return {f"energy_final_{k}": float(last[k]) for k in ("kinetic", "potential", "elastic", "dissipated")}


def _max_fn(res) -> float:
    return float(res.contacts["fn"].max()) if len(res.contacts) else 0.0


def _n_contacts_final(res) -> float:
    c = res.contacts
    return float((c["t"] == c["t"].max()).sum()) if len(c) else 0.0


def _body_final(res) -> dict:
    out = {}
    if not len(res.bodies):
        return out
    last = res.bodies[res.bodies["t"] == res.bodies["t"].max()]
    for _, r in last.iterrows():
        for k in ("x", "y", "z", "vx", "vy", "vz"):
            out[f"{r['body']}.{k}_final"] = float(r[k])
    return out


METRICS: dict[str, Callable] = {
    "energy_final": _energy_final,          # kinetic, potential, elastic, dissipated at the last output time
    "max_fn": _max_fn,                      # largest normal contact force over the run [N]
    "n_contacts_final": _n_contacts_final,  # active contacts at the last output time
    "bodies_final": _body_final,            # position and velocity of every body at the last output time
}
DEFAULT_METRICS = ("energy_final", "max_fn")


def _run_id(scene_text: str, overrides: dict, backend: str) -> str:
    key = json.dumps({"scene": scene_text, "overrides": overrides, "backend": backend}, sort_keys=True, default=str)
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def _cell(v):
    return json.dumps(v) if isinstance(v, (list, dict)) else v


def run_one(scene_path: str, overrides: dict, backend: str, run_dir: str, metrics: tuple[str, ...]) -> dict:
    """Run one variant (on a dask worker or in-process) and return its table row; writes row.json when done."""
    from coupler.errors import BackendUnavailable, SimulationError
    from coupler.run import run_scene
    from coupler.scene import load_scene
    out = Path(run_dir)
    row: dict[str, Any] = {}
    try:
        scene = load_scene(scene_path, overrides=overrides)
        res = run_scene(scene, out, backend=backend, progress=False)
    except (SceneError, SimulationError, BackendUnavailable) as e:
        return {"status": f"failed: {type(e).__name__}: {e}"}
    row["status"] = "done"
    for k, v in res.summary.items():
        if isinstance(v, (bool, int, float, str)) or isinstance(v, np.generic):
            row[f"summary.{k}"] = v.item() if isinstance(v, np.generic) else v
    for name in metrics:
        val = METRICS[name](res)
        if isinstance(val, dict):
            row.update(val)
        else:
            row[name] = float(val)
    (out / "row.json").write_text(json.dumps(row, indent=1, allow_nan=True) + "\n")
    return row


def _client(workers: int | None, scheduler: str | None):
    from distributed import Client, LocalCluster
    if scheduler:
        return Client(scheduler), None
    if workers:
        # each worker process runs its kernels on one numba thread: the OpenMP layer (coupler/__init__.py) slows
        # down many times over when runnable threads outnumber the cores (measured: 9.7 -> 86 ms per MPM step).
        # Results are bitwise identical for any thread count, so this changes only the speed.
        import os
        old = os.environ.get("NUMBA_NUM_THREADS")
        os.environ["NUMBA_NUM_THREADS"] = "1"           # inherited by the worker processes spawned below
        try:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        finally:
            if old is None:
                os.environ.pop("NUMBA_NUM_THREADS", None)
            else:
                os.environ["NUMBA_NUM_THREADS"] = old
        return Client(cluster), cluster
    return Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None), None


def sweep(scene_path: str | Path, varies: list[Vary], out_dir: str | Path, *, seeds: int | None = None,
          backend: str = "native", metrics: tuple[str, ...] = DEFAULT_METRICS, workers: int | None = None,
          scheduler: str | None = None, progress: bool = True) -> pd.DataFrame:
    """Run the sweep (module docstring) and return the table it wrote to out_dir/sweep.csv."""
    from coupler.run import backend_module
    from coupler.scene import load_scene
    scene_path = Path(scene_path).resolve()
    unknown = [m for m in metrics if m not in METRICS]
    if unknown:
        raise SceneError("--metric", f"unknown metric(s) {unknown}; known: {', '.join(METRICS)}")
    if workers is not None and workers < 1:
        raise SceneError("--workers", f"must be >= 1, got {workers}")
    backend_module(backend)                                   # unknown / unavailable backend: fail before running
    base = load_scene(scene_path)                             # a bad scene file fails here, once
    text = scene_path.read_text()
    runs = plan(varies, seeds, base.seed)
    for ov in runs:                                           # a bad override path fails before anything runs
        load_scene(scene_path, overrides=ov)
    out = Path(out_dir).resolve()
    (out / "runs").mkdir(parents=True, exist_ok=True)
    ids = [_run_id(text, ov, backend) for ov in runs]
    rows: dict[int, dict] = {}
    todo = []
    for k, rid in enumerate(ids):
        p = out / "runs" / rid / "row.json"
        if p.exists():
            rows[k] = json.loads(p.read_text())
        else:
            todo.append(k)
    if progress:
        print(f"[sweep] {len(runs)} runs, {len(runs) - len(todo)} already done, {len(todo)} to run", flush=True)
    if todo:
        client, cluster = _client(workers, scheduler)
        try:
            from distributed import as_completed
            futs = {client.submit(run_one, str(scene_path), runs[k], backend, str(out / "runs" / ids[k]),
                                  tuple(metrics), key=f"mpmdem-run-{ids[k]}", pure=False): k for k in todo}
            for n, fut in enumerate(as_completed(futs), 1):
                k = futs[fut]
                rows[k] = fut.result()
                if progress:
                    print(f"[sweep] {n}/{len(todo)} {runs[k]}: {rows[k]['status']}", flush=True)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    table = []
    for k, ov in enumerate(runs):
        table.append({**{f: _cell(v) for f, v in ov.items()}, "backend": backend, "run_id": ids[k], **rows[k]})
    df = pd.DataFrame(table)
    df.to_csv(out / "sweep.csv", index=False, float_format="%.17g")
    try:
        import pyarrow  # noqa: F401
        df.to_parquet(out / "sweep.parquet", index=False)
    except ImportError:
        pass
    return df
