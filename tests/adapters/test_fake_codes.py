"""Issue 17, adapters: a reference code that crashes, dies on a signal, hangs past its timeout, or exits 0 with
missing or garbage output gives one clear error (coupler.errors.ReferenceCodeError; CLI exit 6, one stderr line)
naming the code, what happened and the path of its log. Tested with fakes, no reference code needed: LIGGGHTS and
YADE are found on PATH (a fake `liggghts` / `yade` first on PATH), Kratos runs `run_kratos.py` with
$MPMDEM_KRATOS_PYTHON (adapters/kratos/backend.py kratos_python). Timeouts: MPMDEM_<CODE>_TIMEOUT."""
from __future__ import annotations

import importlib.util
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coupler.errors import ReferenceCodeError
from coupler.run import run_scene
from coupler.scene import load_scene
from tests.conftest import CASES, ROOT

SCENE = Path(CASES, "dem_hertz_impact", "pair.toml")        # two spheres: every adapter maps it

# what each fake does; {pidfile} is where a hanging fake writes the pid of its child (killed with the group)
FAKES = {
    "crash": "echo 'starting'\necho 'ERROR: fake failure in pair style' >&2\nexit 1\n",
    "signal": "echo 'starting'\nkill -SEGV $$\n",
    "hang": "echo 'starting'\nsleep 600 &\necho $! > {pidfile}\nwait\n",
    "no output": "echo 'done'\nexit 0\n",
    "garbage": ("echo 'done'\nprintf 'ITEM: TIMESTEP\\nnot a number\\n@@@\\n' > atoms.dump\n"
                "printf 'ITEM: TIMESTEP\\n0\\nITEM: ENTRIES\\n1 2\\n' > pairs.dump\n"
                "printf 'id,t,x\\nnot,a,table,at,all\\n' > bodies_yade.csv\n"
                "printf 'i,j\\n' > contacts_yade.csv\n"
                "printf '{not json' > timing_yade.json\n"
                "printf '{not json' > timing_kratos.json\nexit 0\n"),
}
EXPECT = {"crash": "exited with code 1", "signal": "was killed by signal SIGSEGV", "hang": "did not finish within",
          "no output": "cannot be parsed", "garbage": "cannot be parsed"}
CODES = {"liggghts": ("LIGGGHTS", "stdout.liggghts"), "yade": ("YADE", "log.yade"), "kratos": ("Kratos", "log.kratos")}


def _fake(tmp_path: Path, backend: str, mode: str, monkeypatch) -> Path:
    """Put the fake in place for `backend`; returns the pid file of a hanging fake's child."""
    bindir = tmp_path / "bin"
    bindir.mkdir(exist_ok=True)
    pidfile = tmp_path / "child.pid"
    exe = bindir / ("kratos-python" if backend == "kratos" else backend)
    exe.write_text("#!/bin/sh\n" + FAKES[mode].replace("{pidfile}", str(pidfile)))
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    if backend == "yade":       # the one-YADE-at-a-time lock guards YADE's fixed ports; a fake opens none (and a
        import contextlib       # real YADE run of another process may hold the lock for minutes)
        import adapters.yade.backend as yb
        monkeypatch.setattr(yb, "exclusive", lambda name: contextlib.nullcontext())
    if backend == "kratos":
        if importlib.util.find_spec("KratosMultiphysics") is None:
            pytest.skip("the Kratos adapter checks the installed Kratos version before it runs (pip install .[kratos])")
        monkeypatch.setenv("MPMDEM_KRATOS_PYTHON", str(exe))
    else:
        monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv(f"MPMDEM_{backend.upper()}_TIMEOUT", "2")
    return pidfile


@pytest.mark.parametrize("mode", list(FAKES))
@pytest.mark.parametrize("backend", list(CODES))
def test_fake_reference_code_gives_one_clear_error(backend, mode, tmp_path, monkeypatch):
    pidfile = _fake(tmp_path, backend, mode, monkeypatch)
    out = tmp_path / "out"
    t0 = time.monotonic()
    with pytest.raises(ReferenceCodeError) as e:
        run_scene(load_scene(SCENE), out, backend=backend, progress=False)
    msg = str(e.value)
    code, log = CODES[backend]
    assert "\n" not in msg and msg.startswith(code + " ") and EXPECT[mode] in msg, msg
    assert f"(log: {out / log})" in msg and (out / log).exists(), msg
    if mode == "crash":
        assert "fake failure in pair style" in msg, msg        # the last log line says what went wrong
    if mode == "hang":
        assert time.monotonic() - t0 < 60, "the 2 s timeout (MPMDEM_<CODE>_TIMEOUT) was not applied"
        child = int(pidfile.read_text())
        for _ in range(50):                                     # the fake's own child went with it (process group)
            if not Path(f"/proc/{child}").exists() or "Z" in Path(f"/proc/{child}/stat").read_text().split()[2]:
                break
            time.sleep(0.1)
        else:
            pytest.fail(f"the hanging code's child process {child} is still running")


@pytest.mark.parametrize("backend,mode", [("liggghts", "crash"), ("liggghts", "hang"), ("kratos", "garbage")])
def test_cli_fake_reference_code_exit_6_one_line(backend, mode, tmp_path, monkeypatch):
    _fake(tmp_path, backend, mode, monkeypatch)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=ROOT)
    p = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(SCENE), "--backend", backend, "--out",
                        str(out), "--quiet"], capture_output=True, text=True, cwd=ROOT, timeout=600, env=env)
    lines = p.stderr.strip().splitlines()
    code, log = CODES[backend]
    assert p.returncode == 6 and len(lines) == 1, (p.returncode, p.stderr[-3000:])
    assert lines[0].startswith(f"error: {code} ") and str(out / log) in lines[0], lines[0]


def test_bad_timeout_variable_is_a_scene_error(monkeypatch):
    from adapters.common import timeout_for
    from coupler.errors import SceneError
    monkeypatch.setenv("MPMDEM_YADE_TIMEOUT", "soon")
    with pytest.raises(SceneError, match="MPMDEM_YADE_TIMEOUT: must be a number of seconds > 0"):
        timeout_for("yade", None)
    assert timeout_for("yade", 5.0) == 5.0
    monkeypatch.delenv("MPMDEM_YADE_TIMEOUT")
    assert timeout_for("yade", None) == 3600.0
