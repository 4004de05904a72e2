"""MPM throughput benchmark: Bui collapse at h = 2.5 mm, 4 points per cell (2 x 2), quadratic B-spline,
Mohr-Coulomb, APIC (the validation scene). Reports material-point steps per second (best of `repeats` timed
blocks of `steps` steps, each block one compiled loop, MPMSolver.advance; the machine is shared: all blocks are
listed), the time per phase of one step, the estimated wall time of the 1 s collapse, and memory per point.

The per-phase split comes from the same compiled step as the timed blocks: MPMSolver.advance(n, profile=True) runs
kernels.step with its per-phase cycle timer on (kernels.PHASES), converted to ms with the cycle rate measured
over that block; it is not a restated copy of the step."""
from __future__ import annotations

import math
import time
from pathlib import Path



SCENE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_bui_collapse" / "scene.toml"


def profile_step(sol, steps: int = 100) -> dict:
    """Milliseconds per step spent in each phase of the compiled step (kernels.PHASES), measured by running
    `steps` steps with the step's own phase timer; "total" is the wall time per step of that block."""
    from coupler.mpm import kernels as K
    sol.timer[:] = 0
    c0, t0 = K.cycles_now(), time.perf_counter()
    sol.advance(steps, profile=True)
    c1, t1 = K.cycles_now(), time.perf_counter()
    rate = (c1 - c0) / (t1 - t0)          # cycles per second over this block
    out = {k: 1e3 * float(c) / rate / steps for k, c in zip(K.PHASES, sol.timer) if c > 0 or k == "check"}
    out["total"] = 1e3 * (t1 - t0) / steps
    return out


def bench_mpm(threads: int = 1, steps: int = 400, repeats: int = 3) -> dict:
    import numba

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    scene = load_scene(SCENE, overrides={"mpm.grid.cell_size": 0.0025, "mpm.shape_function": "bspline2"})
    assert scene.mpm.bodies[0].particles_per_cell == 2 and scene.mpm.bodies[0].model.model == "mohr_coulomb"
    sol = MPMSolver(scene)
    sol.advance(5)  # JIT warm-up (cached kernels compile once per machine)
    n = len(sol.m)
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol.advance(steps)
        rates.append(n * steps / (time.perf_counter() - t0))
    prof = profile_step(sol)
    best = max(rates)
    per_point = [sol.x, sol.x0, sol.v, sol.m, sol.vol0, sol.vol, sol.lp, sol.mid, sol.bid, sol.C, sol.F, sol.s,
                 sol.eps_p, sol.fext, sol.strip_order, sol._scratch, sol._chunk_cost]
    bytes_pp = sum(a.nbytes for a in per_point) / n
    steps_1s = int(math.ceil(1.0 / sol.dt))
    return {"case": "mpm_bui_collapse h=2.5mm, 2x2 points/cell, bspline2, mohr_coulomb, " + sol.ms.transfer,
            "threads": numba.get_num_threads(), "threading_layer": numba.threading_layer(), "points": n,
            "steps": steps, "mp_steps_per_s": best, "mp_steps_per_s_repeats": [float(r) for r in rates],
            "ms_per_step_by_kernel": {k: round(v, 4) for k, v in prof.items()},
            "collapse_1s_steps": steps_1s, "collapse_1s_wall_s_estimate": n * steps_1s / best,
            "bytes_per_point": bytes_pp, "grid_bytes": sol.G.nbytes + sol.V.nbytes,
            "parallel_kernels": "p2g (strip-coloured, deterministic), grid update, gather (g2p + stress) use prange; "
                                "all steps of a block run in one compiled loop (kernels.advance)"}


def bench_mpm_scaling(pairs: int = 7, steps: int = 400, probe: bool = True) -> dict:
    """1 vs 2 threads on the collapse bench, interleaved (coupler/hostprobe.py): two solvers of the same scene, one
    stepped on 1 thread and one on 2, advanced pair by pair by `steps` steps each (both stay in the same state:
    the results are bitwise the same for any thread count), 1-thread and 2-thread blocks alternating with the order
    flipped every pair; the ratio of each pair cancels the host's slow speed drift. probe: the host probe's FMA
    and stream loops are interleaved with the pairs (the same minutes), with its launch cost and the steal time.
    Returns rates (MP-steps/s) per block, pair ratios with median / quartiles / how many below 1.8x and 1.6x, the
    per-phase split at 1 and 2 threads after the pairs (profile_step), and the probe's ratios beside."""
    import numba

    from coupler import hostprobe as hp
    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene

    scene = load_scene(SCENE, overrides={"mpm.grid.cell_size": 0.0025, "mpm.shape_function": "bspline2"})
    sols = {t: MPMSolver(scene) for t in (1, 2)}
    n = len(sols[1].m)

    benches = {"mpm": hp.solver_blocks(sols, n, steps)}
    try:
        for f in benches["mpm"]:
            f()                               # JIT warm-up and the first gather cost measurement
        if probe:
            benches.update(hp.probe_benches())
        rec = hp.scaling_record(hp.interleave_many(benches, pairs), "mpm", probe)
        out = {"case": "mpm_bui_collapse h=2.5mm, 2x2 points/cell, bspline2, mohr_coulomb, " + sols[1].ms.transfer,
               "points": n, "steps_per_block": steps, "pairs": pairs,
               "mp_steps_per_s_1t": rec.pop("rates_1t"), "mp_steps_per_s_2t": rec.pop("rates_2t"), **rec}
        host = out.pop("host")
        for t in (1, 2):
            numba.set_num_threads(t)
            out[f"ms_per_step_by_kernel_{t}t"] = {k: round(v, 4) for k, v in profile_step(sols[t]).items()}
        out["host"] = host
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return out


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys
    print(json.dumps(bench_mpm(int(sys.argv[1]) if len(sys.argv) > 1 else 1), indent=1))
