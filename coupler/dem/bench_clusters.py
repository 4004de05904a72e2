"""Cluster benchmark (issue #4): 2,000 blocks of 6 x 5 glued 5 mm aluminium spheres settling in a box.

The blocks start stacked face to face in a 10 x 20 x 10 (x, y, z) lattice of touching blocks (zero gap, zero
overlap) inside a box of five planes, with random velocities of 0.05 m/s (seeded): contacts between blocks and with
the walls form from the first steps, as in a settling packing. Reported: body-steps and sphere-steps per second and
the number of active contacts at the end of the timed window.
"""
from __future__ import annotations

import time

import numba
import numpy as np

from coupler.scene import loads_scene

TOML = """
name = "bench_clusters"
dimension = 3
gravity = [0.0, -9.81, 0.0]
seed = 1
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
{planes}
"""
NX, NY, NZ = 10, 20, 10
SIZE = (0.030, 0.025, 0.005)          # block extent: 6 x 5 spheres of 5 mm, one sphere thick


def cluster_scene(n_blocks: int, steps: int, speed: float = 0.05):
    if n_blocks > NX * NY * NZ:
        raise ValueError(f"n_blocks must be <= {NX * NY * NZ}")
    rng = np.random.default_rng(1)
    rows = []
    for k in range(n_blocks):
        i, l, j = k % NX, k // (NX * NZ), (k // NX) % NZ
        c = [(i + 0.5) * SIZE[0], (l + 0.5) * SIZE[1], (j + 0.5) * SIZE[2]]
        v = rng.normal(size=3)
        v *= speed / np.linalg.norm(v)
        rows.append(f'[[dem.clusters]]\nname = "b{k}"\ntemplate = "block"\nmaterial = "al"\n'
                    f"position = [{c[0]:.6f}, {c[1]:.6f}, {c[2]:.6f}]\n"
                    f"velocity = [{v[0]:.6f}, {v[1]:.6f}, {v[2]:.6f}]\n")
    box = [("floor", [0, 0, 0], [0, 1, 0]), ("left", [0, 0, 0], [1, 0, 0]),
           ("right", [NX * SIZE[0], 0, 0], [-1, 0, 0]), ("back", [0, 0, 0], [0, 0, 1]),
           ("front", [0, 0, NZ * SIZE[2]], [0, 0, -1])]
    planes = "\n".join(f'[[dem.planes]]\nname = "{n}"\nmaterial = "al"\npoint = {p}\nnormal = {q}\n'
                       for n, p, q in box)
    return loads_scene(TOML.format(t_end=steps * 1e-6, clusters="\n".join(rows), planes=planes),
                       name="bench_clusters")


def bench_clusters(threads: int, n_blocks: int = 2000, steps: int = 300) -> dict:
    from coupler.dem.solver import DEMSolver
    numba.set_num_threads(threads)
    solver = DEMSolver(cluster_scene(n_blocks, steps))
    solver.advance(20)                                   # compile, first contacts
    t0 = time.perf_counter()
    solver.advance(steps)
    wall = time.perf_counter() - t0
    c = solver.c
    active = int(np.count_nonzero(c.pout[:, 8] > 0.0)) + int(np.count_nonzero(c.wout[:, 8] > 0.0))   # overlap > 0
    return {"blocks": n_blocks, "spheres": solver.s.n, "steps": steps, "wall_s": wall,
            "body_steps_per_s": n_blocks * steps / wall, "sphere_steps_per_s": solver.s.n * steps / wall,
            "active_contacts": active, "threads": threads, "parallel_kernels": solver.parallel}
