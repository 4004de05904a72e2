"""Mesh-wall benchmark: glass beads poured onto a static bumpy STL floor of 100,352 triangles (a terrain patch).

The floor is a 224 x 224 grid of squares over 0.2 x 0.2 m, two triangles each, heights 2 mm sin(kx) sin(kz)
(50,625 nodes), written as a binary STL and read through the scene's `file =` (as a user's terrain is). The beads
(radius 1.5-2 mm, seeded random packing) fill the box from 2.1 mm (just above the bumps' crests) to 12 mm (28 % solid) and
fall at 1 m/s: the lowest layer meets the crests from the first steps and the valleys within the timed 2 ms. The same scene runs natively (1 and 2 threads) and in LIGGGHTS
(`fix wall/gran` on the STL, 1 core) for the same steps of the same time step. Reported: sphere-steps per second,
microseconds per step, the beads' mean height at the end (the same physics in both codes) and the mesh contacts
the native run holds at the end. The reference-code run is coupler/bench.py mesh_pour_throughput (it goes through
the backends, a layer above this one).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from coupler.scene import loads_scene

TOML = """
name = "bench_mesh_pour"
dimension = 3
gravity = [0.0, -9.81, 0.0]
seed = 2
[time]
t_end = {t_end}
dt = {dt}
output_interval = {t_end}
[output]
bodies = true
contacts = false
energy = false
[materials.glass]
density = 2500.0
young = 1e8
poisson = 0.25
[[contacts]]
materials = ["glass", "glass"]
restitution = 0.5
friction = 0.4
[dem]
[[dem.packings]]
name = "beads"
material = "glass"
radius_range = [1.5e-3, 2e-3]
box_min = [0.0, 0.0021, 0.0]
box_max = [0.2, 0.012, 0.2]
count = {count}
velocity = [0.0, -1.0, 0.0]
[[dem.meshes]]
name = "floor"
material = "glass"
file = "floor.stl"
rigid = true
"""
CELLS, SIZE, AMPLITUDE = 224, 0.2, 2e-3
DT = 2e-6                      # the automatic step would be 3.7e-6 (Hertz contact time / 10 at 2 m/s)


def terrain(cells: int = CELLS, size: float = SIZE, amplitude: float = AMPLITUDE) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (n+1)^2 x 3 and triangles 2 n^2 x 3 of a bumpy square floor, y = a sin(2 pi x / 0.05) sin(2 pi z / 0.05)."""
    s = np.linspace(0.0, size, cells + 1)
    X, Z = np.meshgrid(s, s, indexing="ij")
    Y = amplitude * np.sin(2 * np.pi * X / 0.05) * np.sin(2 * np.pi * Z / 0.05)
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    a = (i * (cells + 1) + j).ravel()
    b, c, d = a + cells + 1, a + 1, a + cells + 2
    faces = np.concatenate([np.column_stack([a, c, b]), np.column_stack([c, d, b])])   # normals +y
    return nodes, faces


def mesh_pour_scene(folder: Path, count: int = 5000, steps: int = 1000, dt: float = DT):
    import meshio
    nodes, faces = terrain()
    meshio.write(folder / "floor.stl", meshio.Mesh(nodes, [("triangle", faces)]), binary=True)
    return loads_scene(TOML.format(t_end=steps * dt, dt=dt, count=count), name="bench_mesh_pour", base_dir=folder)


def bench_mesh_native(threads: int, count: int = 5000, steps: int = 1000) -> dict:
    from coupler.dem.solver import DEMSolver
    numba.set_num_threads(threads)
    with tempfile.TemporaryDirectory() as d:
        solver = DEMSolver(mesh_pour_scene(Path(d), count, steps))
    solver.advance(1)                                     # kernels loaded, first neighbour build
    t0 = time.perf_counter()
    solver.advance(steps - 1)
    wall = time.perf_counter() - t0
    n = solver.s.n
    return {"spheres": n, "triangles": 2 * CELLS * CELLS, "steps": steps - 1, "wall_s": wall,
            "sphere_steps_per_s": n * (steps - 1) / wall, "us_per_step": 1e6 * wall / (steps - 1),
            "mean_height_m": float(solver.s.x[:, 1].mean()), "mesh_contacts": int(len(solver.mesh_out[0])),
            "threads": threads, "parallel_kernels": bool(solver.parallel)}
