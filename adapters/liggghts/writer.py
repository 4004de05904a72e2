"""Write a LIGGGHTS input script and data file for a DEM scene (spheres + axis-aligned plane walls)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from adapters.liggghts.params import liggghts_restitution
from coupler.dem.timestep import chosen_dt
from coupler.errors import UnsupportedFeature
from coupler.scene import Scene, pair_key

AXES = "xyz"


def check_supported(scene: Scene) -> None:
    dem = scene.dem
    if dem is None or scene.mpm is not None:
        raise UnsupportedFeature("liggghts", "mpm", "LIGGGHTS runs DEM-only scenes")
    if dem.clusters:
        if dem.cluster_damping_mass == "sphere":
            raise UnsupportedFeature("liggghts", "dem.cluster_damping_mass",
                                     "LIGGGHTS multisphere damps with the body mass only (notes P5)")
        raise UnsupportedFeature("liggghts", "dem.clusters", "multisphere export is not written yet in this adapter")
    if dem.meshes:
        raise UnsupportedFeature("liggghts", "dem.meshes", "STL mesh export is not written yet in this adapter")
    for k, p in enumerate(dem.planes):
        if np.count_nonzero(p.normal) != 1:
            raise UnsupportedFeature("liggghts", f"dem.planes[{k}].normal",
                                     "only planes normal to x, y or z map to primitive walls")
        if np.any(p.velocity != 0.0):
            raise UnsupportedFeature("liggghts", f"dem.planes[{k}].velocity", "moving primitive walls")


def box(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    dem = scene.dem
    r = float(dem.radius.max())
    lo, hi = dem.position.min(axis=0), dem.position.max(axis=0)
    for p in dem.planes:
        a = int(np.nonzero(p.normal)[0][0])
        lo[a] = min(lo[a], p.point[a])
        hi[a] = max(hi[a], p.point[a])
    pad = max(20.0 * r, 0.5 * float((hi - lo).max()))
    return lo - pad, hi + pad


def write_inputs(scene: Scene, out: Path) -> dict:
    """Write in.liggghts + data.spheres into out; return run facts (dt, steps, output stride, type map).
    The box shrink-wraps the spheres (`boundary m m m`); data-file bounds only seed it."""
    check_supported(scene)
    dem = scene.dem
    mats = sorted(scene.materials)
    tid = {m: k + 1 for k, m in enumerate(mats)}
    dt = chosen_dt(scene)
    steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    lo, hi = box(scene)
    n = dem.n_spheres
    rho = np.array([scene.materials[m].density for m in dem.material])
    lines = ["LIGGGHTS data file written by mpmdem", "", f"{n} atoms", f"{len(mats)} atom types", ""]
    for a in range(3):
        lines.append(f"{lo[a]:.12g} {hi[a]:.12g} {AXES[a]}lo {AXES[a]}hi")
    lines += ["", "Atoms", ""]
    for i in range(n):
        x = dem.position[i]
        lines.append(f"{i + 1} {tid[dem.material[i]]} {2 * dem.radius[i]:.15g} {rho[i]:.15g} "
                     f"{x[0]:.15g} {x[1]:.15g} {x[2]:.15g}")
    lines += ["", "Velocities", ""]
    for i in range(n):
        v, w = dem.velocity[i], dem.angular_velocity[i]
        lines.append(f"{i + 1} {v[0]:.15g} {v[1]:.15g} {v[2]:.15g} {w[0]:.15g} {w[1]:.15g} {w[2]:.15g}")
    (out / "data.spheres").write_text("\n".join(lines) + "\n")

    def matrix(fn):
        vals = []
        for a in mats:
            for b in mats:
                key = pair_key(a, b)
                vals.append(f"{fn(scene.contacts[key]):.15g}" if key in scene.contacts else "0.5")
        return " ".join(vals)

    skin = dem.skin if dem.skin is not None else 0.3 * float(dem.radius.min())
    g = scene.gravity
    gn = float(np.linalg.norm(g))
    s = [
        "# written by mpmdem (adapters/liggghts); parameter map: adapters/liggghts/params.py",
        "units si", "atom_style granular", "atom_modify map array", "boundary m m m", "newton off",
        "communicate single vel yes", "hard_particles yes",                             # P14
        "read_data data.spheres",
        f"neighbor {skin:.10g} bin", "neigh_modify delay 0",
        "fix m1 all property/global youngsModulus peratomtype " + " ".join(f"{scene.materials[m].young:.15g}" for m in mats),
        "fix m2 all property/global poissonsRatio peratomtype " + " ".join(f"{scene.materials[m].poisson:.15g}" for m in mats),
        f"fix m3 all property/global coefficientRestitution peratomtypepair {len(mats)} {matrix(liggghts_restitution)}",
        f"fix m4 all property/global coefficientFriction peratomtypepair {len(mats)} {matrix(lambda l: l.friction)}",
        "pair_style gran model hertz tangential history limitForce on",                # P2
        "pair_coeff * *",
        f"timestep {dt:.15g}",
    ]
    if gn > 0:
        s.append(f"fix grav all gravity {gn:.15g} vector {g[0] / gn:.15g} {g[1] / gn:.15g} {g[2] / gn:.15g}")
    wall_cols = []
    for k, p in enumerate(dem.planes):
        a = int(np.nonzero(p.normal)[0][0])
        s.append(f"fix w{k} all wall/gran model hertz tangential history primitive type {tid[p.material]} "
                 f"{AXES[a]}plane {p.point[a]:.15g} store_force yes limitForce on")
        wall_cols += [f"f_force_w{k}[1]", f"f_force_w{k}[2]", f"f_force_w{k}[3]"]
    s.append("fix integr all nve/sphere")
    if scene.dimension == 2:
        s.append("fix planar all planeforce 0 0 1")
    cols = ["id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz"] + wall_cols
    s.append(f"dump da all custom {every} atoms.dump {' '.join(cols)}")
    s.append("dump_modify da sort id format \"%d" + " %.15g" * (len(cols) - 1) + "\"")
    if scene.output.contacts and n > 1:
        s.append("compute pc all pair/gran/local id force delta")
        s.append(f"dump dc all local {every} pairs.dump c_pc[1] c_pc[2] c_pc[3] c_pc[4] c_pc[5] c_pc[6] c_pc[7]")
        s.append("dump_modify dc format \"%.0f %.0f %.0f %.15g %.15g %.15g %.15g\"")
    s.append("thermo 100000")
    s.append("thermo_modify lost error")                 # a sphere may never disappear silently
    s.append(f"run {steps}")
    if steps % every:                                     # the final state, like the native output
        s.append("undump da")
        s.append(f"dump df all custom 1 atoms.dump {' '.join(cols)}")
        s.append("dump_modify df sort id append yes format \"%d" + " %.15g" * (len(cols) - 1) + "\"")
        s.append("run 0")
    (out / "in.liggghts").write_text("\n".join(s) + "\n")
    return {"dt": dt, "steps": steps, "every": every, "types": tid, "n_walls": len(dem.planes)}
