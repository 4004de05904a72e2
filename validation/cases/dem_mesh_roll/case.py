"""Mesh wall (issue #4): a sphere rolling (with initial slip, heading diagonally across the triangle edges) on a
floor made of one plane, and on the same floor as a mesh of 2 x 40 x 40 small triangles (2.5 mm cells, i.e. edges
and vertices crossed every few milliseconds). Trajectory difference < 0.1 % of the distance travelled; no force
spike at edges: the largest normal force on the mesh stays within 0.1 % of the plane's, and the number of active
mesh contacts never exceeds one (no double count)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.metrics import peak_force, trajectory_error

TITLE = "Mesh wall: rolling across many small triangles vs one plane"
FULL_ONLY = False


def floor_mesh(n=40, h=2.5e-3, x0=-0.02, z0=-0.02):
    xs, zs = x0 + h * np.arange(n + 1), z0 + h * np.arange(n + 1)
    verts = [[float(x), 0.0, float(z)] for x in xs for z in zs]
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            tris += [[a, d, c], [a, c, b]]        # normals +y
    return verts, tris


def evaluate(ctx):
    plane = ctx.scene("plane.toml")
    verts, tris = floor_mesh()
    mesh = load_scene(ctx.case_dir / "plane.toml", name="roll_mesh", overrides={
        "dem.planes": [], "dem.meshes": [{"name": "floor", "material": "aluminium", "vertices": verts,
                                           "triangles": tris}]})
    rp = ctx.run(plane, tag="plane")
    rm = ctx.run(mesh, tag="mesh")
    bp, bm = rp.body("ball"), rm.body("ball")
    xp, xm = bp[["x", "y", "z"]].to_numpy(), bm[["x", "y", "z"]].to_numpy()
    travelled = float(np.linalg.norm(xp[-1] - xp[0]))
    diff = trajectory_error(xp, xm)
    ctx.check_max("max trajectory difference / distance travelled", diff / travelled, 1e-3,
                  wall_time_s=ctx.wall_times["mesh"], note=f"travelled {travelled * 1e3:.1f} mm")
    cp, cm = rp.contacts, rm.contacts
    ctx.check_rel("largest normal force, mesh vs plane [N]", peak_force(cm["fn"]), peak_force(cp["fn"]), 1e-3,
                  wall_time_s=ctx.wall_times["mesh"])
    ctx.check_max("most simultaneous mesh contacts of the sphere", float(cm.groupby("t").size().max()), 1.0,
                  wall_time_s=ctx.wall_times["mesh"])
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4))
    a1.plot(xp[:, 0], xp[:, 2], label="plane")
    a1.plot(xm[:, 0], xm[:, 2], "--", label="mesh")
    for x in np.arange(-0.02, 0.03, 2.5e-3):
        a1.axvline(x, color="0.85", lw=0.5)
        a1.axhline(x, color="0.85", lw=0.5)
    a1.set(xlabel="x [m]", ylabel="z [m]", title="path over the triangle grid")
    a1.legend()
    a2.plot(cp["t"], cp["fn"], label="plane")
    a2.plot(cm["t"], cm["fn"], "--", label="mesh")
    a2.set(xlabel="t [s]", ylabel="F_n [N]")
    a2.legend()
    ctx.save_plot(fig)
