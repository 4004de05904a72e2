"""The DEM lattice benchmark run in YADE (-j1) through the adapter (same scene as coupler/bench.py), 1 core."""
from __future__ import annotations

import tempfile
from pathlib import Path


def yade_lattice_throughput(nx: int, ny: int, nz: int, steps: int, radius: float, dt: float) -> dict:
    from adapters.yade.backend import run
    from coupler.bench import lattice_scene
    scene = lattice_scene(nx, ny, nz, r=radius, dt=dt, steps=steps)
    with tempfile.TemporaryDirectory() as d:
        res = run(scene, Path(d), timeout_s=3600)
    n = nx * ny * nz
    loop = float(res.summary["loop_time_s"])
    return {"particles": n, "steps": steps, "loop_time_s": loop, "particle_steps_per_s": n * steps / loop,
            "code_version": res.summary["code_version"], "cores": 1}
