"""MPM throughput benchmark: Bui collapse at h = 2.5 mm, 4 points per cell (2 x 2), quadratic B-spline,
Mohr-Coulomb, APIC (the validation scene). Reports material-point steps per second (best of `repeats` timed
blocks, the machine is shared: all blocks are listed), the time per kernel of one step, the estimated wall time of
the 1 s collapse, and memory per point."""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

SCENE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_bui_collapse" / "scene.toml"


def profile_step(sol, steps: int = 100) -> dict:
    """Milliseconds per step spent in each phase of MPMSolver.step (USL/APIC path), timed kernel by kernel."""
    from coupler.mpm import kernels as K
    o, h, dt = sol.org, sol.h, sol.dt
    t = dict.fromkeys(("check", "strip_sort", "p2g", "grid_update", "gather(g2p+stress)"), 0.0)
    for _ in range(steps):
        c0 = time.perf_counter()
        sol._check_positions()
        c1 = time.perf_counter()
        K.strip_sort(sol.kind, sol.x, o[0], h, sol.strip_start, sol._scratch, sol.strip_order)
        c2 = time.perf_counter()
        K.p2g(sol.kind, sol.x, sol.v, sol.C, sol.m, sol.vol, sol.s, sol.lp, sol.fext, o[0], o[1], h, sol.nx,
              sol.ny, sol.g[0], sol.g[1], sol.mode == 2, sol.strip_start, sol.strip_order, sol.G)
        c3 = time.perf_counter()
        K.grid_update(sol.G, dt, sol.V, sol.nx, sol.ny, sol.bc, sol.mu, sol.ms.damping)
        c4 = time.perf_counter()
        K.gather(0, sol.kind, sol.x, sol.v, sol.C, sol.F, sol.vol, sol.vol0, sol.s, sol.eps_p, sol.prm, sol.mid,
                 sol.lp, o[0], o[1], h, sol.nx, sol.ny, dt, sol.V, sol.mode, sol.box)
        c5 = time.perf_counter()
        for k, a, b in zip(t, (c0, c1, c2, c3, c4), (c1, c2, c3, c4, c5)):
            t[k] += b - a
        sol.nstep += 1
        sol.t += dt
    return {k: 1e3 * v / steps for k, v in t.items()}


def bench_mpm(threads: int = 1, steps: int = 400, repeats: int = 3) -> dict:
    import numba

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    scene = load_scene(SCENE, overrides={"mpm.grid.cell_size": 0.0025, "mpm.shape_function": "bspline2"})
    assert scene.mpm.bodies[0].particles_per_cell == 2 and scene.mpm.bodies[0].model.model == "mohr_coulomb"
    sol = MPMSolver(scene)
    for _ in range(5):  # JIT warm-up (cached kernels compile once per machine)
        sol.step()
    n = len(sol.m)
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            sol.step()
        rates.append(n * steps / (time.perf_counter() - t0))
    prof = profile_step(sol) if sol.mode != 1 else {}
    best = max(rates)
    per_point = [sol.x, sol.x0, sol.v, sol.m, sol.vol0, sol.vol, sol.lp, sol.mid, sol.bid, sol.C, sol.F, sol.s,
                 sol.eps_p, sol.fext, sol.strip_order, sol._scratch]
    bytes_pp = sum(a.nbytes for a in per_point) / n
    steps_1s = int(math.ceil(1.0 / sol.dt))
    return {"case": "mpm_bui_collapse h=2.5mm, 2x2 points/cell, bspline2, mohr_coulomb, " + sol.ms.transfer,
            "threads": numba.get_num_threads(), "threading_layer": numba.threading_layer(), "points": n,
            "steps": steps, "mp_steps_per_s": best, "mp_steps_per_s_repeats": [float(r) for r in rates],
            "ms_per_step_by_kernel": {k: round(v, 4) for k, v in prof.items()},
            "collapse_1s_steps": steps_1s, "collapse_1s_wall_s_estimate": n * steps_1s / best,
            "bytes_per_point": bytes_pp, "grid_bytes": sol.G.nbytes + sol.V.nbytes,
            "parallel_kernels": "p2g (strip-coloured, deterministic), grid update, gather (g2p + stress) use prange"}


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys
    print(json.dumps(bench_mpm(int(sys.argv[1]) if len(sys.argv) > 1 else 1), indent=1))
