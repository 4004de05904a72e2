"""Coupled bench: an MPM backfill (Mohr-Coulomb, geostatic) behind a held DEM wall block, plus DEM blocks resting
on the backfill top (a second interface side is not needed: the blocks sit on the same closed-outline wall).
Reports MP-steps/s and DEM particle-steps/s inside the coupled run and the coupling's own cost per step (mapping,
interface wall update, exchange) against the MPM + DEM cost of the same step.

    python3 -m coupler.coupling.bench [--steps N] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from coupler.coupling.solver import CoupledRun
from coupler.scene import load_scene

SCENE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "coupled_earth_pressure" / "scene.toml"


def bench_scene():
    extra = "\n".join(f"""
[[dem.clusters]]
name = "block{k}"
template = "bar"
material = "concrete"
position = [{0.2 + 0.15 * k:.3f}, 0.5125, 0.0]
""" for k in range(5))
    text = SCENE.read_text().replace("[[dem.clusters]]", "[dem.templates.bar]\ngrid = { nx = 4, ny = 1, radius = "
                                     "0.0125, spacing = 0.025 }\n\n[[dem.clusters]]", 1)
    text = text.replace('sides = ["left"]', 'sides = ["left", "top"]')
    text = text.replace("dem_substeps = 3 ", 'dem_substeps = "auto" ')
    text = text.replace("\n[mpm]\n", extra + "\n[mpm]\n", 1)
    from coupler.scene import loads_scene
    return loads_scene(text, name="coupled_bench", base_dir=SCENE.parent)


def run_bench(steps: int = 500, warm: int = 20, cpu: bool = False) -> dict:
    """cpu: time the parts with the thread's CPU time (time.thread_time) instead of the wall clock: on a shared
    machine the wall clock also counts the time other jobs hold the core."""
    run = CoupledRun(bench_scene())
    if cpu:
        run.scheme.clock = time.thread_time
    for _ in range(warm):
        run.step()
    T = run.scheme.timers
    for k in T:
        T[k] = 0.0
    t0 = time.perf_counter()
    for _ in range(steps):
        run.step()
    wall = time.perf_counter() - t0
    own = T["map"] + T["interface"] + T["exchange"]
    solvers = T["dem"] + T["mpm"]
    nmp, nsph = run.mpm.n_points(), run.dem.n_spheres()
    return {"coupling_steps": steps, "dem_substeps": run.substeps, "mpm_points": nmp, "dem_spheres": nsph,
            "wall_s": wall, "per_step_us": {k: 1e6 * v / steps for k, v in T.items()},
            "mp_steps_per_s": nmp * steps / T["mpm"], "dem_particle_steps_per_s": nsph * steps * run.substeps / T["dem"],
            "coupling_own_over_solvers": own / solvers, "clock": "thread CPU time" if cpu else "wall clock"}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m coupler.coupling.bench")
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--out", default=None)
    p.add_argument("--cpu", action="store_true", help="time the parts with the thread CPU time (shared machine)")
    a = p.parse_args(argv)
    res = run_bench(a.steps, cpu=a.cpu)
    print(json.dumps(res, indent=2))
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        (Path(a.out) / "coupled_bench.json").write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
