"""The native backend: builds only the solvers the scene declares (DEM, MPM, or both through the coupling)."""
from __future__ import annotations

from pathlib import Path

from coupler import __version__
from coupler.checkpoint import Restart
from coupler.errors import SceneError, UnsupportedFeature
from coupler.results import Result
from coupler.scene import Scene


def run(scene: Scene, out_dir: Path, *, progress: bool = True, timeout_s: float | None = None,
        restart: Restart | None = None, keep_tables: bool = True) -> Result:
    """Run `scene` in-process. `timeout_s` is not used (the native solvers run in this process, not a subprocess).
    restart: checkpoints to write and/or resume from (coupler/checkpoint.py). keep_tables = False: the tables
    that grow with bodies x output times stay on disk (results.StreamedResult)."""
    out = Path(out_dir)
    if scene.mpm is not None and scene.gravity_schedule is not None:     # MPM-only and coupled runs alike
        raise UnsupportedFeature("native (MPM)", "gravity_schedule", "the MPM solver uses a constant gravity")
    if scene.coupling is not None:
        from coupler.coupling.solver import run_coupled
        result = run_coupled(scene, out, progress=progress, restart=restart, keep_tables=keep_tables)
    elif scene.mpm is not None and scene.dem is None:
        from coupler.mpm.solver import run_mpm
        result = run_mpm(scene, out, progress=progress, restart=restart, keep_tables=keep_tables)
    elif scene.dem is not None and scene.mpm is None:
        from coupler.dem.solver import run_dem
        result = run_dem(scene, out, progress=progress, restart=restart, keep_tables=keep_tables)
    else:
        raise SceneError("coupling", "a scene with both [dem] and [mpm] needs a [coupling] table")
    import numba
    result.summary.setdefault("code_version", f"mpmdem {__version__}")
    result.summary.setdefault("threads", numba.get_num_threads())     # the wall time's context (mpmdem run --threads)
    return result
