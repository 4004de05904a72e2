"""Typed access to raw TOML tables with field-path error messages.

Every scene section parser (DEM, MPM, coupling, ...) reads its table through a `Table`, so an unknown key,
a missing field or a value out of range raises one `SceneError` naming the dotted path and the allowed range.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from coupler.errors import SceneError

_MISSING = object()


def _fmt(v: Any) -> str:
    return repr(v) if isinstance(v, str) else str(v)


class Table:
    """A TOML table being parsed. Call `done()` at the end: any key not read is reported as unknown."""

    def __init__(self, raw: Any, path: str):
        if not isinstance(raw, dict):
            raise SceneError(path or "<scene>", f"must be a table, got {type(raw).__name__}")
        self.raw = raw
        self.path = path
        self._read: set[str] = set()

    def sub(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.raw

    def _get(self, key: str, default: Any) -> Any:
        self._read.add(key)
        if key in self.raw:
            return self.raw[key]
        if default is _MISSING:
            raise SceneError(self.sub(key), "missing required field")
        return default

    def raw_value(self, key: str, default: Any = _MISSING) -> Any:
        return self._get(key, default)

    def table(self, key: str, default: Any = _MISSING) -> "Table | None":
        v = self._get(key, default)
        if v is None:
            return None
        return Table(v, self.sub(key))

    def tables(self, key: str) -> list["Table"]:
        """An array of tables (``[[key]]``); absent means empty."""
        v = self._get(key, [])
        if not isinstance(v, list):
            raise SceneError(self.sub(key), f"must be an array of tables ([[{key}]]), got {type(v).__name__}")
        return [Table(item, f"{self.sub(key)}[{i}]") for i, item in enumerate(v)]

    def named_tables(self, key: str) -> dict[str, "Table"]:
        """A table of tables keyed by name (``[key.name]``); absent means empty."""
        v = self._get(key, {})
        if not isinstance(v, dict):
            raise SceneError(self.sub(key), f"must be a table of named tables, got {type(v).__name__}")
        return {name: Table(item, f"{self.sub(key)}.{name}") for name, item in v.items()}

    def number(self, key: str, default: Any = _MISSING, *, gt: float | None = None, ge: float | None = None,
               lt: float | None = None, le: float | None = None) -> float:
        v = self._get(key, default)
        if v is None:
            return v
        return check_number(self.sub(key), v, gt=gt, ge=ge, lt=lt, le=le)

    def integer(self, key: str, default: Any = _MISSING, *, ge: int | None = None, le: int | None = None) -> int:
        v = self._get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise SceneError(self.sub(key), f"must be an integer, got {_fmt(v)}")
        if ge is not None and v < ge:
            raise SceneError(self.sub(key), f"must be >= {ge}, got {v}")
        if le is not None and v > le:
            raise SceneError(self.sub(key), f"must be <= {le}, got {v}")
        return int(v)

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        v = self._get(key, default)
        if not isinstance(v, bool):
            raise SceneError(self.sub(key), f"must be true or false, got {_fmt(v)}")
        return v

    def string(self, key: str, default: Any = _MISSING, *, choices: Iterable[str] | None = None) -> str:
        v = self._get(key, default)
        if v is None:
            return v
        if not isinstance(v, str):
            raise SceneError(self.sub(key), f"must be a string, got {_fmt(v)}")
        if choices is not None:
            choices = list(choices)
            if v not in choices:
                raise SceneError(self.sub(key), f"must be one of {', '.join(map(repr, choices))}; got {v!r}")
        return v

    def vector(self, key: str, n: int, default: Any = _MISSING, *, positive: bool = False) -> np.ndarray | None:
        v = self._get(key, default)
        if v is None:
            return None
        return check_vector(self.sub(key), v, n, positive=positive)

    def done(self) -> None:
        unknown = [k for k in self.raw if k not in self._read]
        if unknown:
            k = unknown[0]
            known = sorted(self._read)
            raise SceneError(self.sub(k), f"unknown key (allowed here: {', '.join(known) if known else 'none'})")


def check_number(path: str, v: Any, *, gt=None, ge=None, lt=None, le=None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise SceneError(path, f"must be a number, got {_fmt(v)}")
    v = float(v)
    if not math.isfinite(v):
        raise SceneError(path, f"must be finite, got {v}")
    rng = []
    if gt is not None:
        rng.append(f"> {gt:g}")
    if ge is not None:
        rng.append(f">= {ge:g}")
    if lt is not None:
        rng.append(f"< {lt:g}")
    if le is not None:
        rng.append(f"<= {le:g}")
    bad = ((gt is not None and not v > gt) or (ge is not None and not v >= ge)
           or (lt is not None and not v < lt) or (le is not None and not v <= le))
    if bad:
        what = " and ".join(rng)
        if len(rng) == 2:
            lo = f"({gt:g}" if gt is not None else (f"[{ge:g}" if ge is not None else "(-inf")
            hi = f"{lt:g})" if lt is not None else (f"{le:g}]" if le is not None else "inf)")
            what = f"in {lo}, {hi}"
        raise SceneError(path, f"must be {what}, got {v:g}")
    return v


def check_vector(path: str, v: Any, n: int, *, positive: bool = False) -> np.ndarray:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise SceneError(path, f"must be a list of {n} numbers, got {_fmt(v)}")
    out = np.array([check_number(f"{path}[{i}]", x, gt=0.0 if positive else None) for i, x in enumerate(v)])
    return out
