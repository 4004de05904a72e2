"""Cluster benchmark: blocks of 6 x 5 glued 5 mm spheres settling in a box (issue #4); body-steps per second."""
from __future__ import annotations

import math
import time

import numba

from coupler.scene import loads_scene

TOML = """
name = "bench_clusters"
dimension = 3
gravity = [0.0, -9.81, 0.0]
[time]
t_end = {t_end}
dt = 1e-6
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
[dem.templates.block]
grid = {{ nx = 6, ny = 5, radius = 2.5e-3, spacing = 5e-3 }}
{clusters}
[[dem.planes]]
name = "floor"
material = "al"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
"""


def cluster_scene(n_blocks: int, steps: int):
    per_row = int(math.ceil(n_blocks ** (1 / 3)))
    rows = []
    for k in range(n_blocks):
        i, j, l = k % per_row, (k // per_row) % per_row, k // per_row ** 2
        rows.append(f'[[dem.clusters]]\nname = "b{k}"\ntemplate = "block"\nmaterial = "al"\n'
                    f"position = [{0.04 * i:.4f}, {0.0126 + 0.03 * l:.4f}, {0.01 * j:.4f}]\n")
    return loads_scene(TOML.format(t_end=steps * 1e-6, clusters="\n".join(rows)), name="bench_clusters")


def bench_clusters(threads: int, n_blocks: int = 2000, steps: int = 200) -> dict:
    from coupler.dem.solver import DEMSolver
    numba.set_num_threads(threads)
    solver = DEMSolver(cluster_scene(n_blocks, steps))
    solver.advance(5)
    t0 = time.perf_counter()
    solver.advance(steps)
    wall = time.perf_counter() - t0
    return {"blocks": n_blocks, "spheres": solver.s.n, "steps": steps, "wall_s": wall,
            "body_steps_per_s": n_blocks * steps / wall, "sphere_steps_per_s": solver.s.n * steps / wall,
            "threads": threads, "note": "cluster steps use the serial kernels and a Python step loop"}
