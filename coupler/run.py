"""Dispatch: one Scene, many backends. The native backend builds only the solvers the scene declares."""
from __future__ import annotations

import time
from pathlib import Path

from coupler import __version__
from coupler.errors import BackendUnavailable, SceneError
from coupler.results import Result
from coupler.scene import Scene

BACKENDS = ("native", "liggghts", "yade", "kratos")


def run_scene(scene: Scene, out_dir: str | Path, backend: str = "native", progress: bool = True,
              timeout_s: float | None = None) -> Result:
    """Run `scene` on `backend`, write the result tables into out_dir and return them."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if backend == "native":
        result = _run_native(scene, out, progress)
    elif backend == "liggghts":
        from adapters.liggghts.backend import run as run_liggghts
        result = run_liggghts(scene, out, timeout_s=timeout_s)
    elif backend == "yade":
        from adapters.yade.backend import run as run_yade
        result = run_yade(scene, out, timeout_s=timeout_s)
    elif backend == "kratos":
        try:
            from adapters.kratos.backend import run as run_kratos
        except ImportError:
            raise BackendUnavailable("the Kratos adapter is not written yet (adapters/kratos)") from None
        result = run_kratos(scene, out, timeout_s=timeout_s)
    else:
        raise SceneError("--backend", f"must be one of {', '.join(BACKENDS)}; got {backend!r}")
    result.summary.setdefault("scene", scene.name)
    result.summary.setdefault("backend", backend)
    result.summary.setdefault("wall_time_s", time.perf_counter() - t0)
    result.summary.setdefault("scene_hash", scene.text_hash)
    result.check()
    result.write(out)
    return result


def _run_native(scene: Scene, out: Path, progress: bool) -> Result:
    if scene.coupling is not None:
        from coupler.coupling.solver import run_coupled
        result = run_coupled(scene, out, progress=progress)
    elif scene.mpm is not None and scene.dem is None:
        if scene.gravity_schedule is not None:
            from coupler.errors import UnsupportedFeature
            raise UnsupportedFeature("native (MPM)", "gravity_schedule", "the MPM solver uses a constant gravity")
        from coupler.mpm.solver import run_mpm
        result = run_mpm(scene, out, progress=progress)
    elif scene.dem is not None and scene.mpm is None:
        from coupler.dem.solver import run_dem
        result = run_dem(scene, out, progress=progress)
    else:
        raise SceneError("coupling", "a scene with both [dem] and [mpm] needs a [coupling] table")
    result.summary.setdefault("code_version", f"mpmdem {__version__}")
    return result
