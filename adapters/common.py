"""Shared by the reference-code adapters: finding the binary, running it with a timeout and a kept log,
provenance records."""
from __future__ import annotations

import fcntl
import json
import math
import os
import shutil
import signal
import subprocess
import time
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from coupler.errors import BackendUnavailable, ReferenceCodeError, SceneError, UnsupportedFeature


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


DEFAULT_TIMEOUT_S = 3600.0


def timeout_for(code: str, timeout_s: float | None) -> float:
    """A reference run's timeout [s]: the caller's timeout_s, else the environment variable MPMDEM_<CODE>_TIMEOUT
    (e.g. MPMDEM_LIGGGHTS_TIMEOUT=600), else one hour."""
    if timeout_s:
        return float(timeout_s)
    var = f"MPMDEM_{code.upper()}_TIMEOUT"
    raw = os.environ.get(var)
    if raw is None:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise SceneError(var, f"must be a number of seconds > 0, got {raw!r}")
    return value


def _last_line(log: Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return (lines[-1][:200] + ("..." if len(lines[-1]) > 200 else "")) if lines else ""


def run_logged(cmd: list[str], cwd: Path, log_name: str, timeout_s: float | None, code: str | None = None) -> float:
    """Run cmd in cwd (its own process group, OMP_NUM_THREADS=1); stdout+stderr go to cwd/log_name. Returns the
    wall time. A non-zero exit, a death by a signal or a run past timeout_s (the whole process group is killed) is
    a ReferenceCodeError naming `code` (default: the program name), what happened and the log."""
    code = code or Path(cmd[0]).name
    log = cwd / log_name
    t0 = time.perf_counter()
    env = dict(os.environ, OMP_NUM_THREADS="1")
    with open(log, "w") as fh:
        try:
            proc = subprocess.Popen(cmd, cwd=cwd, stdout=fh, stderr=subprocess.STDOUT, env=env,
                                    stdin=subprocess.DEVNULL, start_new_session=True)
        except OSError as e:
            raise ReferenceCodeError(code, f"could not be started: {e.strerror} ({cmd[0]})", log) from None
        try:
            rc = proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            raise ReferenceCodeError(code, f"did not finish within its timeout of {timeout_s:g} s and was killed "
                                           f"(MPMDEM_{code.upper()}_TIMEOUT sets it)", log) from None
        except BaseException:             # KeyboardInterrupt: do not leave the reference code running
            _kill_group(proc)
            raise
    wall = time.perf_counter() - t0
    if rc != 0:
        how = f"was killed by signal {signal.Signals(-rc).name}" if rc < 0 and -rc in signal.valid_signals() \
            else f"exited with code {rc}"
        last = _last_line(log)
        raise ReferenceCodeError(code, how + (f"; last log line: {last!r}" if last else "; its log is empty"), log)
    return wall


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


# what reading a reference code's output files raises when they are missing, truncated or garbage
# (RuntimeError: the parsers' own consistency checks, e.g. LIGGGHTS bodies that match no scene cluster)
PARSE_ERRORS = (OSError, ValueError, KeyError, IndexError, StopIteration, TypeError, ZeroDivisionError, RuntimeError)


@contextmanager
def parsing(code: str, log: Path, out: Path):
    """Reading `code`'s output files in `out`: an exception from unparsable output becomes one ReferenceCodeError
    naming the code and its log (a SceneError from the scene side passes unchanged)."""
    try:
        yield
    except (SceneError, ReferenceCodeError, BackendUnavailable):
        raise
    except PARSE_ERRORS as e:
        first = (str(e).strip().splitlines() or [""])[0][:200]
        raise ReferenceCodeError(code, f"wrote output in {out} that cannot be parsed ({type(e).__name__}: {first})",
                                 log) from e


def check_reached_end(code: str, log: Path, times, scene) -> None:
    """The parsed tables reach the end of the run (within one output interval and one step): a reference code that
    stopped early and still exited 0 is not a silently shorter result."""
    t_last = float(max(times)) if len(times) else -math.inf
    t_end, oi = scene.time.t_end, scene.time.output_interval
    if not t_last >= t_end - oi * (1.0 + 1e-6) - (scene.time.dt or 0.0):
        raise ReferenceCodeError(code, f"output ends at t = {t_last:.6g} s, the run asked for t_end = {t_end:g} s "
                                       f"(output every {oi:g} s)", log)


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
