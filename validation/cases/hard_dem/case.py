"""Hard cases, DEM (issue #17): stability where DEM codes break. Each scene is run at the automatic step
(coupler/dem/timestep.py); tolerances:

  fast_mesh.toml     a steel sphere at 50 m/s against a zero-thickness mesh plate of two triangles. No tunnelling:
                     the sphere centre never reaches the plate plane (largest x <= 0 m); rebound speed / impact
                     speed = e within 0.5 % (the Hertz impact tolerance of dem_hertz_impact); no mesh contact
                     dropped. A forced step of 2R/v (the sphere would jump across the plate in one step) must be
                     refused at load time with the tunnelling error naming time.dt (1 = refused as such).
  steel_rubber.toml  steel (210 GPa) and rubber (10 MPa) spheres on one steel plane: the automatic step must be
                     set by a steel contact (the stiffest; 1 = yes), and both rebounds deliver their pair's e within
                     0.5 % (an under-resolved steel contact would not).
  mass_ratio.toml    a 10 mm steel sphere resting on a 1 mm one (mass ratio 1000) on a steel plane, 0.25 s: the
                     contact forces at the end equal the weights above them (0.1 %, as coupled_resting_load), and
                     the overlaps equal the static Hertz overlaps of those forces (0.5 %: the force 0.1 % gives
                     0.07 % in overlap; the rest is the remaining oscillation). The centres are on one vertical
                     line, so the (unstable) stack stays symmetric: it tests the time step, not the stability of the
                     stack. The heavy sphere's bounce is damped slowly: the dashpot uses m* ~ the small mass.
  resting_block.toml a 30-sphere block resting on a plane for >= 10^6 automatic steps: after it settled (t >= 0.04
                     s), drift of the centre <= 1e-6 R (2.5 nm) in x and y, of the rotation <= 1e-9 rad.
  settling.toml      a dense pack settling for 1 s (validation/cases/hard_common/settling.py): 2,000 spheres
                     here; the 50,000-sphere pack is hard_dem_settling_full (--full only)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.errors import SceneError
from coupler.scene import load_scene
from validation.cases.hard_common.settling import settling_checks

TITLE = "Hard cases, DEM: 50 m/s on a thin mesh, steel + rubber, mass ratio 1:1000, 10^6 resting steps, settling"
FULL_ONLY = False
HERTZ_TOL = 5e-3


def _run(ctx, name: str):
    """(scene, result, wall time) of this case's scene file <name>.toml."""
    scene = ctx.scene(f"{name}.toml")
    res = ctx.run(scene, tag=name)
    return scene, res, ctx.wall_times[name]


def _fast_mesh(ctx, ax):
    scene, res, wall = _run(ctx, "fast_mesh")
    b = res.bodies
    v0 = float(scene.dem.velocity[0, 0])
    e = scene.contact_law("steel", "steel").restitution
    ctx.check_max("fast_mesh: largest x of the sphere centre (plate at x = 0) [m]", float(b["x"].max()), 0.0,
                  wall_time_s=wall, note="no tunnelling through the zero-thickness plate")
    ctx.check_rel("fast_mesh: rebound / impact speed", float(-b["vx"].iloc[-1] / v0), e, HERTZ_TOL, wall_time_s=wall)
    ctx.check_abs("fast_mesh: mesh contacts dropped", float(res.summary["mesh_contacts_dropped"]["total"]), 0.0, 0.0,
                  wall_time_s=wall)
    r = float(scene.dem.radius[0])
    dt_bad = 2.0 * r / v0
    try:
        load_scene(scene.source, overrides={"time.dt": dt_bad})
        msg, ok = "accepted", False
    except SceneError as err:
        msg = str(err)
        ok = msg.startswith("time.dt") and "tunnel" in msg
    ctx.check_abs(f"fast_mesh: forced dt = 2R/v = {dt_bad:g} s refused as tunnelling [1 = yes]", float(ok), 1.0, 0.0,
                  note=msg)
    ax.plot(b["t"] * 1e6, b["x"] * 1e3, label="sphere centre x [mm]")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("t [us]")
    ax.set_title(f"50 m/s on a thin mesh (dt {res.summary['dt']:.3g} s)", fontsize=9)
    ax.legend(fontsize=8)


def _steel_rubber(ctx, ax):
    scene, res, wall = _run(ctx, "steel_rubber")
    why = res.summary["dt_limit_reason"]
    ctx.check_abs("steel_rubber: automatic step set by a steel contact [1 = yes]", float("steel" in why), 1.0, 0.0,
                  wall_time_s=wall, note=f"dt {res.summary['dt']:.4g} s: {why}")
    b = res.bodies
    for name, mat in zip(scene.dem.names, scene.dem.material):
        g = b[b["body"] == name]
        e = scene.contact_law(mat, "steel").restitution
        ctx.check_rel(f"steel_rubber: {name} rebound / impact speed", float(g["vy"].iloc[-1] / -g["vy"].iloc[0]), e,
                      HERTZ_TOL, wall_time_s=wall)
        ax.plot(g["t"] * 1e3, g["vy"], label=name)
    ax.set_xlabel("t [ms]")
    ax.set_ylabel("vy [m/s]")
    ax.set_title("steel and rubber on a steel plane", fontsize=9)
    ax.legend(fontsize=8)


def _hertz_overlap(force, estar, rstar):
    return (3.0 * force / (4.0 * estar * math.sqrt(rstar))) ** (2.0 / 3.0)


def _mass_ratio(ctx, ax):
    scene, res, wall = _run(ctx, "mass_ratio")
    steel = scene.materials["steel"]
    g = -float(scene.gravity[1])
    rs, rl = (float(r) for r in scene.dem.radius)
    m = steel.density * 4.0 / 3.0 * math.pi * np.array([rs, rl]) ** 3
    estar = 1.0 / (2.0 * (1.0 - steel.poisson ** 2) / steel.young)      # steel on steel (the plane is elastic)
    c = res.contacts
    last = c[c["t"] == c["t"].max()]
    for label, j, force, rstar in (("small on floor", "wall:floor", (m[0] + m[1]) * g, rs),
                                   ("heavy on small", "heavy", m[1] * g, rs * rl / (rs + rl))):
        row = last[last["j"] == j].iloc[0]
        ctx.check_rel(f"mass_ratio: {label} normal force [N]", float(row["fn"]), force, 1e-3, wall_time_s=wall,
                      note="weight above the contact")
        ctx.check_rel(f"mass_ratio: {label} overlap [m]", float(row["overlap"]), _hertz_overlap(force, estar, rstar),
                      5e-3, wall_time_s=wall, note="static Hertz overlap of that weight")
        cc = c[c["j"] == j]
        ax.plot(cc["t"], cc["fn"] / force, label=label)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("normal force / weight above")
    ax.set_title(f"mass ratio {m[1] / m[0]:.0f}: settling", fontsize=9)
    ax.legend(fontsize=8)


def _resting_block(ctx, ax):
    scene, res, wall = _run(ctx, "resting_block")
    steps = int(res.summary["steps"])
    ctx.check_max("resting_block: steps run, -1 x (>= 10^6)", -float(steps), -1e6, wall_time_s=wall,
                  note=f"{steps} steps of dt {res.summary['dt']:.4g} s (auto)")
    b = res.bodies
    b = b[b["t"] >= 0.04 - 1e-9]
    r = float(scene.dem.templates["block6x5"].radii.min())
    for col in ("x", "y"):
        d = b[col].to_numpy() - b[col].iloc[0]
        ctx.check_max(f"resting_block: drift of the centre in {col} / R", float(np.abs(d).max()) / r, 1e-6,
                      wall_time_s=wall, note="from t = 0.04 s (settled) to the end")
        ax.plot(b["t"], d / r, label=f"{col} - {col}(0.04 s), / R")
    ang = 2.0 * np.arctan2(b["qz"].to_numpy(), b["qw"].to_numpy())
    ctx.check_max("resting_block: drift of the rotation [rad]", float(np.abs(ang - ang[0]).max()), 1e-9,
                  wall_time_s=wall)
    ax.set_xlabel("t [s]")
    ax.set_title(f"resting block, {steps} steps", fontsize=9)
    ax.legend(fontsize=8)


def evaluate(ctx):
    fig, ax = plt.subplots(1, 5, figsize=(24, 4.2))
    _fast_mesh(ctx, ax[0])
    _steel_rubber(ctx, ax[1])
    _mass_ratio(ctx, ax[2])
    _resting_block(ctx, ax[3])
    s = settling_checks(ctx, ctx.scene("settling.toml"), "settling", "settling (2,000 spheres)")
    ax[4].semilogy(s["t"], s["kinetic"], label="kinetic")
    if math.isfinite(s["t_star"]):
        ax[4].axvline(s["t_star"], color="k", ls=":", label="t* (after the impacts)")
    ax[4].set_xlabel("t [s]")
    ax[4].set_ylabel("J")
    ax[4].set_title("dense pack settling, 2,000 spheres", fontsize=9)
    ax[4].legend(fontsize=8)
    fig.tight_layout()
    ctx.save_plot(fig)
