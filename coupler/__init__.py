"""mpmdem: partitioned MPM-DEM coupler (scene -> backend -> result tables -> metrics -> report)."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

__version__ = "0.1.0"


def _numba_cache_dir() -> None:
    """Compiled kernels are cached in a folder keyed by the hash of the sources that hold kernels (coupler/dem,
    coupler/mpm, and coupler/contact_models.py whose model codes they compile in).

    numba invalidates a cached function only when its own file changes, not when a kernel it calls (in another
    file) changes; keying the whole cache on the kernel sources avoids running stale machine code after an edit,
    while an edit elsewhere (coupling, results, cli) keeps the cache.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    h = hashlib.sha256()
    root = Path(__file__).resolve().parent
    sources = sorted(list((root / "dem").rglob("*.py")) + list((root / "mpm").rglob("*.py"))
                     + [root / "contact_models.py"])
    for p in sources:
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
