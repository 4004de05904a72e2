"""MPM throughput benchmark: Bui collapse at h = 2.5 mm, 4 points per cell (2 x 2), quadratic B-spline,
Mohr-Coulomb, APIC (the validation scene). Reports material-point steps per second and memory per point."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

SCENE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_bui_collapse" / "scene.toml"


def bench_mpm(threads: int = 1, steps: int = 400) -> dict:
    import numba

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    scene = load_scene(SCENE, overrides={"mpm.grid.cell_size": 0.0025, "mpm.shape_function": "bspline2"})
    assert scene.mpm.bodies[0].particles_per_cell == 2 and scene.mpm.bodies[0].model.model == "mohr_coulomb"
    sol = MPMSolver(scene)
    for _ in range(5):  # JIT warm-up (cached kernels compile once per machine)
        sol.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        sol.step()
    wall = time.perf_counter() - t0
    n = len(sol.m)
    per_point = [sol.x, sol.x0, sol.v, sol.m, sol.vol0, sol.vol, sol.lp, sol.mid, sol.bid, sol.C, sol.F, sol.s,
                 sol.eps_p, sol.fext]
    bytes_pp = sum(a.nbytes for a in per_point) / n
    grid_bytes = sum(a.nbytes for a in (sol.gm, sol.gp, sol.gf, sol.gv0, sol.gv1))
    return {"case": "mpm_bui_collapse h=2.5mm, 2x2 points/cell, bspline2, mohr_coulomb, " + sol.ms.transfer,
            "threads": numba.get_num_threads(), "points": n, "steps": steps, "wall_s": wall,
            "mp_steps_per_s": n * steps / wall, "bytes_per_point": bytes_pp, "grid_bytes": grid_bytes,
            "parallel_kernels": "g2p and stress update use prange; p2g scatter is serial"}


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys
    print(json.dumps(bench_mpm(int(sys.argv[1]) if len(sys.argv) > 1 else 1), indent=1))
