"""`mpmdem run --threads N` (coupler/cli.py set_threads): the native solvers run on N numba threads, summary.json
says how many, the tables are the same bytes for 1 and 2 threads; N outside 1 .. NUMBA_NUM_THREADS, or a reference
backend, is one line naming the flag (exit 2)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numba
import pytest

BAR = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_elastic_bar" / "scene.toml"


def _run(scene: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(scene), "--out", str(out), "--quiet",
                           *extra], capture_output=True, text=True)


@pytest.fixture
def short_bar(tmp_path) -> Path:
    text = BAR.read_text().replace("t_end = 0.2 ", "t_end = 0.01 ", 1)
    assert text != BAR.read_text()
    p = tmp_path / "bar.toml"
    p.write_text(text)
    return p


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 cores (NUMBA_NUM_THREADS >= 2)")
def test_threads_set_the_solver_and_keep_the_results(short_bar, tmp_path):
    for n in (1, 2):
        r = _run(short_bar, tmp_path / str(n), "--threads", str(n))
        assert r.returncode == 0, r.stderr
        assert json.loads((tmp_path / str(n) / "summary.json").read_text())["threads"] == n
    a = {p.name: p.read_bytes() for p in sorted((tmp_path / "1").glob("*.csv"))}
    b = {p.name: p.read_bytes() for p in sorted((tmp_path / "2").glob("*.csv"))}
    assert len(a) >= 3 and a == b


@pytest.mark.parametrize("extra", [("--threads", "0"), ("--threads", str(numba.config.NUMBA_NUM_THREADS + 1)),
                                   ("--threads", "1", "--backend", "liggghts")])
def test_bad_threads_is_one_line_exit_2(short_bar, tmp_path, extra):
    r = _run(short_bar, tmp_path / "x", *extra)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--threads" in r.stderr, r.stderr
