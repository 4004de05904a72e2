"""Shared by the reference-code adapters: finding the binary, running it with a timeout and a kept log,
provenance records."""
from __future__ import annotations

import fcntl
import json
import math
import os
import shutil
import subprocess
import time
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from coupler.errors import BackendUnavailable, UnsupportedFeature


def find_binary(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        raise BackendUnavailable(f"'{name}' is not installed (Debian: apt-get install -y {name})")
    return path


def package_version(pkg: str) -> str:
    """Debian package version (e.g. liggghts 3.8.0+repack1-9+b2), or 'unknown'."""
    try:
        out = subprocess.run(["dpkg-query", "-W", "-f=${Version}", pkg], capture_output=True, text=True, timeout=20)
        return f"{pkg} {out.stdout.strip()}" if out.returncode == 0 and out.stdout.strip() else f"{pkg} unknown"
    except (OSError, subprocess.TimeoutExpired):
        return f"{pkg} unknown"


@contextmanager
def exclusive(lock_name: str):
    """One process at a time (YADE opens fixed local ports even with -n)."""
    with open(f"/tmp/mpmdem-{lock_name}.lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def run_logged(cmd: list[str], cwd: Path, log_name: str, timeout_s: float | None) -> float:
    """Run cmd in cwd; stdout+stderr go to cwd/log_name. Returns wall time; raises RuntimeError with the log tail."""
    log = cwd / log_name
    t0 = time.perf_counter()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    try:
        with open(log, "w") as fh:
            proc = subprocess.run(cmd, cwd=cwd, stdout=fh, stderr=subprocess.STDOUT, timeout=timeout_s, env=env,
                                  stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"{cmd[0]} timed out after {timeout_s} s (log: {log})") from None
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-15:])
        raise RuntimeError(f"{cmd[0]} exited with {proc.returncode} (log: {log}):\n{tail}")
    return wall


def write_provenance(out: Path, code: str, version: str, command: list[str], scene_hash: str, **extra) -> dict:
    prov = {"code": code, "version": version, "command": " ".join(command),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "scene_hash": scene_hash, **extra}
    (out / "provenance.json").write_text(json.dumps(prov, indent=2) + "\n")
    return prov


@dataclass
class Prescribed:
    """A cluster's prescribed motion as the reference-code writers need it (native semantics, coupler/dem/solver.py
    advance + clusters.body_kick): the body moves with `velocity` / `angular_velocity` (zero for "fixed") from t = 0,
    feeling its contacts without responding to them, for the first `release_step` steps (ceil(until/dt - 1e-9), as the
    native solver's step chunking), and is integrated freely from the next step on, starting from v = velocity,
    w = angular_velocity. release_step is None when `until` is not reached within the run."""
    index: int
    name: str
    kind: str
    velocity: np.ndarray
    angular_velocity: np.ndarray
    release_step: int | None


def prescribed_motions(code: str, scene, dt: float, steps: int) -> list[Prescribed]:
    """The scene's prescribed cluster motions (`[[dem.clusters]] motion`), one row per prescribed cluster.
    UnsupportedFeature for an `until` shorter than one step (the native solver then holds the body for its whole
    first advance chunk, an artefact of its output chunking that no reference code reproduces)."""
    out = []
    for k, c in enumerate(scene.dem.clusters if scene.dem is not None else ()):
        m = getattr(c, "motion", None)
        if m is None:
            continue
        release = None
        if math.isfinite(m.until):
            if m.until < dt:
                raise UnsupportedFeature(code, f"dem.clusters[{k}].motion.until",
                                         f"must be >= one time step ({dt:g} s) or omitted, got {m.until:g}")
            n = int(math.ceil(m.until / dt - 1e-9))
            release = n if n < steps else None
        out.append(Prescribed(k, c.name, m.kind, np.asarray(m.velocity, float).copy(),
                              np.asarray(m.angular_velocity, float).copy(), release))
    return out
