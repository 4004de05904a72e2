"""mpmdem: partitioned MPM-DEM coupler (scene -> backend -> result tables -> metrics -> report)."""
from __future__ import annotations

import ast
import hashlib
import os
import re
from pathlib import Path

__version__ = "0.1.0"

# One BLAS/LAPACK thread unless the user chose otherwise (read when scipy's OpenBLAS loads, after this line): the
# solvers' parallel work is numba's; the implicit MPM's banded LU (a few thousand dofs) gains nothing from BLAS
# threads, and on the shared 2-core machine their spinning cost 0.91 s CPU per solve against 0.0086 s with one
# thread (Bui h = 5 mm, 1,848 dofs, half-band 93; coupler/mpm/implicit/solver.py).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


KERNEL_MARKS = re.compile(r"njit|intrinsic|jitclass|structref|@overload|vectorize")


def kernel_sources(root: Path) -> list[Path]:
    """The files whose content can change compiled machine code: every file under coupler/dem, coupler/mpm and
    coupler/contact_models.py that defines numba code, and every project module those import, transitively (a
    kernel bakes the module-level constants it reads, e.g. N_PRM, into its code). Orchestration that only calls
    kernels (solver.py, scene.py, bench.py) is left out, so editing it keeps the cache; so are imports under
    `if TYPE_CHECKING:` (types for annotations only)."""
    cands = sorted(list((root / "dem").rglob("*.py")) + list((root / "mpm").rglob("*.py")) + [root / "contact_models.py"])
    todo = [p for p in cands if KERNEL_MARKS.search(p.read_text())]
    seen: set[Path] = set()
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        tree = ast.parse(p.read_text())
        typing_only = {id(n) for top in ast.walk(tree) if isinstance(top, ast.If) and _is_type_checking(top.test)
                       for stmt in top.body for n in ast.walk(stmt)}
        for node in ast.walk(tree):
            if id(node) in typing_only:             # `if TYPE_CHECKING:` imports never reach compiled code
                continue
            mods = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                    [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                    if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else [])
            for m in mods:
                if m.split(".")[0] != root.name:
                    continue
                base = root.parent.joinpath(*m.split("."))
                todo += [f for f in (base.with_suffix(".py"), base / "__init__.py") if f.is_file()]
    return sorted(seen)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _numba_cache_dir() -> None:
    """Compiled kernels are cached in a folder keyed by the hash of kernel_sources().

    numba invalidates a cached function only when its own file changes, not when a kernel it calls (in another
    file) or a constant it reads changes; keying the whole cache on every file that can change compiled code avoids
    running stale machine code after an edit, while an edit elsewhere (solvers' orchestration, coupling, results,
    cli) keeps the cache.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    h = hashlib.sha256()
    root = Path(__file__).resolve().parent
    for p in kernel_sources(root):
        h.update(p.relative_to(root).as_posix().encode())
        h.update(p.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "mpmdem" / "numba"
    import numba
    numba.config.CACHE_DIR = str(base / h.hexdigest()[:16])
    try:  # keep the folders of the 8 most recent source versions
        old = sorted((d for d in base.iterdir() if d.is_dir()), key=lambda d: d.stat().st_mtime)[:-8]
        import shutil
        for d in old:
            shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


_numba_cache_dir()


def _threading_layer() -> None:
    """numba's threading layer for every solver: OpenMP first, then workqueue, then TBB, unless the user chose one
    with NUMBA_THREADING_LAYER or a parallel function already ran in this process (the layer is fixed at the first
    launch). numba's TBB layer (picked by default when libtbb is installed, as on this machine with the Debian TBB
    2021.8) leaks on every parallel launch (numba/numba#10225): the launch cost grows without bound, measured here
    from 38 us to 1.8 ms per launch over 10,000 launches of an empty prange, so a DEM or MPM run (two to six
    launches per step) slows down step after step. Set here, not in one solver package, so that the DEM (which
    runs first in `mpmdem bench`) does not fix TBB for the MPM that follows."""
    if os.environ.get("NUMBA_THREADING_LAYER"):
        return
    import numba
    from numba.np.ufunc import parallel
    if not parallel._is_initialized:
        numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]


_threading_layer()
