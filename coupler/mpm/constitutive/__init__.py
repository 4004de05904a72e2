"""Constitutive laws as plug-ins (issue 18): one module per law (API in base.py), one registry line per law.

    REGISTRY: law name -> module. The law id packed into slot 0 of a body's parameter row is the law's position
    in REGISTRY.

The compiled dispatch `stress_update(prm, ...)` / `stress_tangent(prm, ..., T)` is generated from REGISTRY when
this package is first imported (a small module written next to the numba cache, named by the hash of its text, so
numba caches it like any source file): one branch per registered law on prm[0], each calling that law's
`update` / `tangent`. Adding a law = its module + one line below; nothing else changes.
`stress_update` is inlined into its callers (the explicit gather, the implicit assembly): as a called function it
took 55 ns per point on the 12,800-point Mohr-Coulomb bench against 33 ns inlined (best of 60 blocks, the same
bits; the call passes the row view prm with its reference count), ~0.28 ms of a ~2.5 ms step (thirteenth session).
An unknown law name is a SceneError at parse time (coupler/mpm/scene.py), and `law(name)` raises KeyError.
"""
from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from dataclasses import dataclass

from coupler.mpm.constitutive.base import N_PRM, RateParams, dp_plane_strain_match  # noqa: F401

REGISTRY: dict[str, str] = {
    "elastic": "coupler.mpm.constitutive.elastic",
    "mohr_coulomb": "coupler.mpm.constitutive.mohr_coulomb",
    "drucker_prager": "coupler.mpm.constitutive.drucker_prager",
}
LAW_ID: dict[str, int] = {name: k for k, name in enumerate(REGISTRY)}
LAWS = tuple(REGISTRY)


def law(name: str):
    """The module of a registered law."""
    return importlib.import_module(REGISTRY[name])


def pack(params) -> np.ndarray:
    """Packed float row of a law's parameter object (slot 0 = the law id)."""
    mod = type(params).__module__
    name = next(n for n, m in REGISTRY.items() if m == mod)
    row = list(params.pack())
    row[0] = LAW_ID[name]
    if len(row) != N_PRM:
        raise ValueError(f"law {name!r}: packed row has {len(row)} entries, the kernels read {N_PRM}")
    return np.array(row, dtype=np.float64)


@dataclass(frozen=True)
class ModelParams:
    """The `constitutive` table of a body as parsed from the scene (law name + every parameter a law may read);
    `law_params()` is the law's own immutable parameter object, `pack()` its packed row."""
    model: str
    young: float
    poisson: float
    friction_angle: float = 0.0   # degrees
    cohesion: float = 0.0
    dilatancy: float = 0.0        # degrees
    rate: RateParams | None = None
    disconnected: bool = False    # zero-stress state below the packing density (constitutive/disconnected.py)

    def law_params(self):
        return law(self.model).Params.from_model(self)

    def pack(self):
        return pack(self.law_params())


ARGS = "prm, sxx, syy, sxy, szz, dxx, dyy, gxy, w, dt"


def dispatch_source() -> str:
    """Text of the generated dispatch module (one branch per registered law)."""
    lines = ['"""Generated from coupler.mpm.constitutive.REGISTRY (do not edit)."""', "from numba import njit", ""]
    for k, (name, mod) in enumerate(REGISTRY.items()):
        lines.append(f"from {mod} import update as _u{k}, tangent as _t{k}  # {name}")
    n = len(REGISTRY)
    for fn, pre, extra, deco in (("stress_update", "_u", "", "@njit(cache=True, inline=\"always\")"),
                                 ("stress_tangent", "_t", ", T", "@njit(cache=True, inline=\"always\")")):
        lines += ["", "", deco, f"def {fn}({ARGS}{extra}):", "    model = int(prm[0])"]
        for k in range(n - 1):
            lines.append(f"    {'if' if k == 0 else 'elif'} model == {k}:")
            lines.append(f"        return {pre}{k}({ARGS}{extra})")
        lines.append(f"    return {pre}{n - 1}({ARGS}{extra})" if n > 1 else f"    return {pre}0({ARGS}{extra})")
    return "\n".join(lines) + "\n"


def _load_dispatch():
    import numba
    src = dispatch_source()
    tag = hashlib.sha256(src.encode()).hexdigest()[:16]
    base = Path(numba.config.CACHE_DIR or os.path.join(tempfile.gettempdir(), "mpmdem-numba"))
    path = base / f"mpm_constitutive_dispatch_{tag}.py"
    if not path.exists() or path.read_text() != src:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(src)
        os.replace(tmp, path)
    name = f"coupler.mpm.constitutive._dispatch_{tag}"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


_dispatch = _load_dispatch()
stress_update = _dispatch.stress_update
stress_tangent = _dispatch.stress_tangent
