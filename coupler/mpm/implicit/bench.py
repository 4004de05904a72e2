"""Implicit MPM throughput: the Bui collapse scene (bspline2, APIC, Mohr-Coulomb, geostatic start) with
`scheme = "implicit"` at cell size h, dt = cfl h / c. Runs `steps` steps from the start (the collapse is under
way: plastic flow, friction base) after a 2-step warm-up and reports MP-steps/s, Newton iterations per step (mean /
max), step cuts, line-search halvings and the time split assembly (residual + tangent, numba) / linear solve
(LAPACK) / update (P2G, dof numbering, G2P), and the same per Newton iteration with the Python remainder
(profile.split). The machine is shared: a single timed block, say so;
the process CPU time of the block is given too (one numba thread: CPU ~ wall on an idle machine). threads: numba
threads (default 1, the Kratos comparison's; with more, the assembly and the twisted band LU run in parallel).
`overrides`: further scene overrides, e.g. the discretization of a Kratos run (adapters/kratos/params.py
native_same_discretization: linear shapes, no-slip base, stress-free start, Kratos' dt, FLIP), named in
`case`."""
from __future__ import annotations

import time
from pathlib import Path

SCENE = Path(__file__).resolve().parents[3] / "validation" / "cases" / "mpm_bui_implicit" / "scene.toml"


def bench_implicit(h: float = 0.005, steps: int = 40, cfl: float = 5.0, linear_solver: str = "direct",
                   overrides: dict | None = None, label: str | None = None, threads: int = 1) -> dict:
    import numba
    import numpy as np

    from coupler.mpm.implicit.profile import reset, split
    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene

    numba.set_num_threads(threads)
    scene = load_scene(SCENE, overrides={"mpm.grid.cell_size": h, "mpm.implicit.cfl": cfl,
                                         "mpm.implicit.linear_solver": linear_solver, **(overrides or {})})
    sol = MPMSolver(scene)
    sol.advance(2)
    reset(sol.stats)
    n = len(sol.m)
    t0, c0 = time.perf_counter(), time.process_time()
    sol.advance(steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    its = sol.stats["newton_iterations"]
    step = f"dt {sol.dt:.3g} s" if overrides and "time.dt" in overrides else f"cfl {cfl:g} (dt {sol.dt:.3g} s)"
    return {"case": f"mpm_bui_implicit h={h * 1000:g}mm, {step}, {linear_solver}" + (f", {label}" if label else "")
            + f", {threads} thread{'s' if threads > 1 else ''}", "threads": threads,
            "points": n, "steps": steps, "dt": sol.dt, "wall_s": wall, "cpu_s": cpu,
            "mp_steps_per_s": n * steps / wall, "mp_steps_per_cpu_s": n * steps / cpu,
            "newton_iterations_mean": float(np.mean(its)), "newton_iterations_max": int(max(its)),
            "step_cuts": sol.stats["cuts"], "line_search_halvings": sol.stats["line_search_halvings"],
            "split_s": {"assembly": sol.stats["assembly_s"], "solve": sol.stats["solve_s"],
                        "update": sol.stats["update_s"]},
            "per_iteration": split(sol.stats, wall)}


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys
    print(json.dumps(bench_implicit(*(float(a) for a in sys.argv[1:2])), indent=1))
