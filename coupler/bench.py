"""`mpmdem bench`: throughput of the native solvers, as ratios against the reference codes run on the same
machine in the same run. Results: printed table + reports/bench.json. Never used as a test assertion."""
from __future__ import annotations

import json
import platform
import time
from pathlib import Path
from typing import Callable

import numba

from coupler.scene import loads_scene

LIGGGHTS_GOAL_RATIO = 1.5   # issue #3: at least 1.5x LIGGGHTS on one core

LATTICE_TOML = """
name = "bench_lattice"
dimension = 3
gravity = [0.0, -9.81, 0.0]
[time]
t_end = {t_end}
dt = {dt}
output_interval = {t_end}
[output]
bodies = false
contacts = false
energy = false
[materials.al]
density = 2700.0
young = 70e9
poisson = 0.33
[[contacts]]
materials = ["al", "al"]
restitution = 0.8
friction = 0.3
[dem]
skin = {skin}
[[dem.lattices]]
name = "lat"
material = "al"
radius = {r}
origin = [{r}, {r}, {r}]
counts = [{nx}, {ny}, {nz}]
[[dem.planes]]
name = "floor"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
[[dem.planes]]
name = "xlo"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [1.0, 0.0, 0.0]
[[dem.planes]]
name = "xhi"
material = "al"
point = [{lx}, 0.0, 0.0]
normal = [-1.0, 0.0, 0.0]
[[dem.planes]]
name = "zlo"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
[[dem.planes]]
name = "zhi"
material = "al"
point = [0.0, 0.0, {lz}]
normal = [0.0, 0.0, -1.0]
"""


def lattice_scene(nx: int = 20, ny: int = 50, nz: int = 20, r: float = 2.5e-3, dt: float = 1e-6, steps: int = 1000):
    """Simple-cubic lattice of touching aluminium spheres in a box under gravity (Hertz + history)."""
    text = LATTICE_TOML.format(t_end=dt * steps, dt=dt, skin=0.1 * r, r=r, nx=nx, ny=ny, nz=nz,
                               lx=2 * r * nx, lz=2 * r * nz)
    return loads_scene(text, name="bench_lattice")


def bench_lattice_native(threads: int, nx=20, ny=50, nz=20, steps=1000) -> dict:
    from coupler.dem.solver import DEMSolver
    numba.set_num_threads(threads)
    scene = lattice_scene(nx, ny, nz, steps=steps)
    solver = DEMSolver(scene)
    solver.advance(5)                       # compile / warm up outside the timed loop
    t0 = time.perf_counter()
    solver.advance(steps)
    wall = time.perf_counter() - t0
    n = solver.s.n
    mem = solver.memory_bytes()
    return {"particles": n, "steps": steps, "wall_s": wall, "particle_steps_per_s": n * steps / wall,
            "threads": threads, "parallel_kernels": solver.parallel,
            "bytes_per_sphere": mem["spheres"] / n, "contact_bytes": mem["contacts"],
            "neighbour_rebuilds": solver.c.rebuilds}


def lattice_throughput(code: str, nx: int, ny: int, nz: int, steps: int, radius: float, dt: float) -> dict:
    """The DEM lattice benchmark scene run in a reference code through its backend (coupler/run.py), 1 core;
    throughput from the code's own loop time (setup and file output excluded)."""
    import tempfile
    from coupler.run import run_scene
    scene = lattice_scene(nx, ny, nz, r=radius, dt=dt, steps=steps)
    with tempfile.TemporaryDirectory() as d:
        res = run_scene(scene, Path(d), backend=code, progress=False, timeout_s=3600)
    n = nx * ny * nz
    loop = float(res.summary["loop_time_s"])
    return {"particles": n, "steps": steps, "loop_time_s": loop, "particle_steps_per_s": n * steps / loop,
            "code_version": res.summary["code_version"], "cores": 1}


def _optional(label: str, fn: Callable[[], dict]) -> dict:
    try:
        return fn()
    except ImportError as e:
        return {"available": False, "reason": f"{label} not available: {e}"}
    except Exception as e:  # a reference code that is missing or fails is reported, not hidden
        return {"available": False, "reason": f"{label} failed: {type(e).__name__}: {e}"}


KRATOS_BUI_BENCH = "validation.cases.mpm_bui_collapse.kratos_bench"     # resolved by name (no upward import)


def run_bench(out: Path, quick: bool = False) -> dict:
    max_threads = numba.config.NUMBA_NUM_THREADS
    threads = [1, 2] if max_threads >= 2 else [1]
    steps = 200 if quick else 1000
    res: dict = {"machine": {"node": platform.node(), "cpu_count": max_threads,
                             "python": platform.python_version(), "numba": numba.__version__},
                 "quick": quick}
    lat = {f"native_{t}t": bench_lattice_native(t, steps=steps) for t in threads}

    lat["liggghts_1core"] = _optional("LIGGGHTS", lambda: lattice_throughput("liggghts", 20, 50, 20, steps, 2.5e-3, 1e-6))
    lat["yade_1core"] = (_optional("YADE", lambda: lattice_throughput("yade", 20, 50, 20, steps, 2.5e-3, 1e-6))
                         if not quick else {"available": False, "reason": "skipped in --quick"})
    for ref in ("liggghts_1core", "yade_1core"):
        r = lat[ref]
        if r.get("particle_steps_per_s"):
            for t in threads:
                lat[f"ratio_native_{t}t_vs_{ref}"] = lat[f"native_{t}t"]["particle_steps_per_s"] / r["particle_steps_per_s"]
    res["dem_lattice_20k"] = lat

    def clusters():
        from coupler.dem.bench_clusters import bench_clusters
        return {f"{t}t": bench_clusters(t) for t in threads}

    def mpm():
        from coupler.mpm.bench import bench_mpm
        r = {f"{t}t": bench_mpm(t) for t in threads}
        if "1t" in r and "2t" in r:     # issue 13 goal: >= 8e6 MP-steps/s on 1 thread, >= 1.8x that on 2
            r["speedup_2t_vs_1t"] = r["2t"]["mp_steps_per_s"] / r["1t"]["mp_steps_per_s"]
        return r

    res["dem_clusters"] = _optional("cluster bench", clusters) if not quick else {"skipped": "--quick"}
    res["mpm_collapse"] = _optional("MPM bench", mpm) if not quick else {"skipped": "--quick"}

    def coupled():   # MPM backfill + held DEM wall + DEM blocks (coupler/coupling/bench.py), one thread
        from coupler.coupling.bench import run_bench as bench_coupled
        numba.set_num_threads(1)
        return bench_coupled(steps=300)

    res["coupled"] = _optional("coupled bench", coupled) if not quick else {"skipped": "--quick"}

    def kratos_bui():   # native (this run) vs Kratos (stored runs, provenance) on the Bui collapse (issue 16)
        import importlib
        return importlib.import_module(KRATOS_BUI_BENCH).bench()

    res["mpm_bui_native_vs_kratos"] = (_optional("Kratos Bui comparison", kratos_bui) if not quick
                                       else {"skipped": "--quick"})
    numba.set_num_threads(max_threads)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(res, indent=2) + "\n")
    return res


def print_bench(res: dict) -> None:
    lat = res["dem_lattice_20k"]
    print("DEM lattice (20,000 touching Al spheres, Hertz + history, dt 1e-6):")
    for k, v in lat.items():
        if isinstance(v, dict) and v.get("particle_steps_per_s"):
            print(f"  {k:<22s} {v['particle_steps_per_s'] / 1e6:8.3f} M particle-steps/s")
        elif isinstance(v, dict):
            print(f"  {k:<22s} {v.get('reason', v)}")
        else:
            print(f"  {k:<22s} {v:8.3f}x")
    r1 = lat.get("ratio_native_1t_vs_liggghts_1core")
    if r1 is not None:
        print(f"  goal: >= {LIGGGHTS_GOAL_RATIO}x LIGGGHTS on one core -> {'met' if r1 >= LIGGGHTS_GOAL_RATIO else 'NOT met'}")
    n1 = lat.get("native_1t", {})
    if n1:
        print(f"  memory: {n1['bytes_per_sphere']:.0f} bytes per sphere (+{n1['contact_bytes'] / 1e6:.1f} MB contacts)")
    for key in ("dem_clusters", "mpm_collapse", "coupled"):
        print(f"{key}: {json.dumps(res.get(key), indent=None)[:600]}")
    kb = res.get("mpm_bui_native_vs_kratos") or {}
    if "kratos" in kb:
        print("MPM Bui collapse, native explicit (this run) vs Kratos implicit (stored runs):")
        for tag, k in kb["kratos"].items():
            if "wall_time_s" not in k:
                print(f"  kratos {tag}: {k.get('reason')}")
                continue
            n = kb["native"].get(tag, {})
            print(f"  {tag}: kratos {k['wall_time_s']:.0f} s ({k['source']}), RMS {k['surface_rms_m'] * 1e3:.2f} mm"
                  + (f"; native {n['wall_time_s']:.2f} s, RMS {n['surface_rms_m'] * 1e3:.2f} mm; equal h "
                     f"{kb[f'ratio_equal_h_{tag}']:.0f}x" if n else ""))
            e = kb.get(f"ratio_equal_error_{tag}", {})
            if e.get("ratio"):
                print(f"    equal error: native h={e['native_cell_size'] * 1e3:g} mm -> {e['ratio']:.0f}x (goal >= "
                      f"{kb['goal_equal_error']:g}x: {'met' if e['goal_met'] else 'NOT met'})")
    elif kb:
        print(f"mpm_bui_native_vs_kratos: {kb}")
