"""Dispatch: one Scene, many backends.

Every backend is a module with `run(scene, out_dir, *, progress, timeout_s) -> Result` that fills the same result
tables (coupler/results.py); BACKENDS is the one table naming them. This module imports none of them until a run
asks for one, and none of them imports this module: adding a backend is one BACKENDS row and its module.
"""
from __future__ import annotations

import importlib
import time
from dataclasses import dataclass
from pathlib import Path

from coupler.checkpoint import Restart
from coupler.errors import BackendUnavailable, SceneError
from coupler.results import Result
from coupler.scene import Scene


@dataclass(frozen=True)
class Backend:
    module: str            # provides run(scene, out_dir, *, progress, timeout_s) -> Result
    missing: str = ""      # BackendUnavailable message when this version does not have the module


BACKENDS: dict[str, Backend] = {
    "native": Backend("coupler.native"),
    "liggghts": Backend("adapters.liggghts.backend"),
    "yade": Backend("adapters.yade.backend"),
    "kratos": Backend("adapters.kratos.backend", missing="the Kratos adapter is not written yet (adapters/kratos)"),
}


def backend_module(backend: str):
    """The module of a registered backend (SceneError for an unknown name, BackendUnavailable when not written)."""
    if backend not in BACKENDS:
        raise SceneError("--backend", f"must be one of {', '.join(BACKENDS)}; got {backend!r}")
    b = BACKENDS[backend]
    try:
        return importlib.import_module(b.module)
    except ModuleNotFoundError as e:
        if b.missing and (b.module + ".").startswith(f"{e.name}."):     # the module or its package is absent
            raise BackendUnavailable(b.missing) from None
        raise


def run_scene(scene: Scene, out_dir: str | Path, backend: str = "native", progress: bool = True,
              timeout_s: float | None = None, restart: Restart | None = None, keep_tables: bool = True) -> Result:
    """Run `scene` on `backend`, write the result tables into out_dir and return them. restart: checkpoints
    (native backend only; coupler/checkpoint.py). keep_tables = False (native backend): the bodies, contacts and
    MPM snapshots are written as the run goes and not held in memory; the returned Result reads them back from
    out_dir when used (results.StreamedResult; `mpmdem run`)."""
    out = Path(out_dir)
    kw = {}
    if restart is not None and restart.asked:
        if backend != "native":
            flag = "--resume" if restart.resume else "--checkpoint-every"
            raise SceneError(flag, f"only the native backend writes and reads checkpoints (got --backend {backend}; "
                                   "LIGGGHTS and YADE restart from their own files: write_restart, O.save)")
        kw["restart"] = restart
    if not keep_tables and backend == "native":
        kw["keep_tables"] = False
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = backend_module(backend).run(scene, out, progress=progress, timeout_s=timeout_s, **kw)
    result.summary.setdefault("scene", scene.name)
    result.summary.setdefault("backend", backend)
    result.summary.setdefault("wall_time_s", time.perf_counter() - t0)
    result.summary.setdefault("scene_hash", scene.text_hash)
    result.check()
    result.write(out, scene)
    return result
