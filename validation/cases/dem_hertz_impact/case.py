"""Head-on Hertz impacts, sphere-wall and sphere-sphere (R = 2.5 mm Al, E = 70 GPa, nu = 0.33, rho = 2700,
v = 1 m/s). e = 1: peak force, maximum overlap and contact duration against the elastic Hertz solution (0.5 %).
e from 0.1 to 0.95 with the default damping mode "restitution": measured restitution = asked (0.5 %).
Damping modes "liggghts" and "yade" at e = 0.8: measured restitution = that of the clamped Hertz ODE with the
code's own beta (0.5 %), i.e. the native law reproduces each code's definition.
Contact time: zero crossings of the gap, linearly interpolated between 10 ns samples (metrics.contact_time_from_gap).
Radii, masses, moduli and impact speeds are read from the scene files."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.dem.contact import beta_liggghts, beta_yade, effective_young, restitution_clamped
from validation.analytic import hertz_impact
from validation.metrics import (contact_time_from_gap, max_overlap, pair_gap, peak_force, restitution_pair,
                                restitution_wall, scene_sphere_props, wall_gap)

TITLE = "Hertz impact: sphere-wall and sphere-sphere vs analytic, restitution sweep"
FULL_ONLY = False
SWEEP = (0.1, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95)
RTOL = 0.005


def _gap_series(res, kind, scene):
    if kind == "wall":
        b = res.body("ball")
        return b["t"].to_numpy(), wall_gap(b, scene_sphere_props(scene, "ball")["radius"]), b
    a, b = res.body("a"), res.body("b")
    gap = pair_gap(a, b, scene_sphere_props(scene, "a")["radius"], scene_sphere_props(scene, "b")["radius"])
    return a["t"].to_numpy(), gap, b


def hertz_reference(scene, kind):
    """Elastic Hertz solution for the scene's impact: wall (sphere 'ball' on the first plane, y = 0) or pair
    (equal spheres 'a' and 'b'), E*, R*, m* and the approach speed from the scene."""
    if kind == "wall":
        s = scene_sphere_props(scene, "ball")
        wall_mat = scene.materials[scene.dem.planes[0].material]
        return hertz_impact(effective_young(s["material"], wall_mat), s["radius"], s["mass"], -float(s["velocity"][1]))
    a, b = scene_sphere_props(scene, "a"), scene_sphere_props(scene, "b")
    assert a["radius"] == b["radius"] and a["mass"] == b["mass"], "pair: equal spheres"
    return hertz_impact(effective_young(a["material"], b["material"]), a["radius"] / 2, a["mass"] / 2,
                        float(a["velocity"][1] - b["velocity"][1]))


def evaluate(ctx):
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(17, 4.5))
    for kind in ("wall", "pair"):
        scene = ctx.scene(f"{kind}.toml")
        ref = hertz_reference(scene, kind)
        res = ctx.run(scene)
        wall = ctx.wall_times[f"{scene.name}_native"]
        c = res.contacts
        t, gap, _ = _gap_series(res, kind, scene)
        ctx.check_rel(f"{kind}: peak force [N]", peak_force(c["fn"]), ref["peak_force"], RTOL, wall_time_s=wall)
        ctx.check_rel(f"{kind}: max overlap [m]", max_overlap(c["overlap"]), ref["max_overlap"], RTOL,
                      wall_time_s=wall)
        ctx.check_rel(f"{kind}: contact time [s]", contact_time_from_gap(t, gap), ref["contact_time"], RTOL,
                      wall_time_s=wall)
        cc = c.groupby("t")["fn"].sum()
        ax1.plot(cc.index * 1e6, cc.values, label=f"{kind} native (e=1)")
        ax1.axhline(ref["peak_force"], ls=":", color="k", lw=0.8)

        # restitution: default mode over the sweep (wall), e = 0.8 for the pair
        for e in (SWEEP if kind == "wall" else (0.8,)):
            res_e = ctx.run(_variant(ctx, kind, e, "restitution"),
                            tag=f"{kind}_e{e}")
            ctx.check_rel(f"{kind}: restitution, asked e={e}", _restitution(res_e, kind), e, RTOL,
                          wall_time_s=ctx.wall_times[f"{kind}_e{e}"])
            if kind == "wall":
                ax2.plot([e], [_restitution(res_e, kind)], "o", color="C0")
        for mode, beta in (("liggghts", beta_liggghts(0.8)), ("yade", beta_yade(0.8))):
            res_m = ctx.run(_variant(ctx, kind, 0.8, mode), tag=f"{kind}_{mode}")
            expect = restitution_clamped(beta)
            ctx.check_rel(f"{kind}: restitution, damping='{mode}' e=0.8", _restitution(res_m, kind), expect, RTOL,
                          wall_time_s=ctx.wall_times[f"{kind}_{mode}"],
                          note=f"reference: clamped Hertz ODE with beta={beta:.6g}")
    _dt_study(ctx, ax3)
    ax1.set_xlabel("t [µs]")
    ax1.set_ylabel("normal force [N]")
    ax1.set_title("elastic impact (dotted: Hertz peak force)")
    ax1.legend()
    ax2.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax2.set_xlabel("asked restitution")
    ax2.set_ylabel("measured restitution (wall)")
    ax2.set_title("damping = 'restitution'")
    ctx.save_plot(fig)


def _dt_study(ctx, ax):
    """Speed against error: elastic wall impact at several dt; velocity Verlet should converge at order 2."""
    from coupler.scene import load_scene
    ref = hertz_reference(ctx.scene("wall.toml"), "wall")
    dts = (4e-7, 2e-7, 1e-7, 5e-8)
    errs, walls = [], []
    for dt in dts:
        sc = load_scene(ctx.case_dir / "wall.toml", overrides={"time.dt": dt, "time.output_interval": dt,
                                                                "output.energy": False, "output.contacts": False}, name=f"wall_dt{dt:g}")
        res = ctx.run(sc, tag=f"wall_dt{dt:g}")
        walls.append(ctx.wall_times[f"wall_dt{dt:g}"])
        t, gap, _ = _gap_series(res, "wall", sc)
        errs.append(abs(contact_time_from_gap(t, gap) - ref["contact_time"]) / ref["contact_time"])
    order = float(np.polyfit(np.log(dts), np.log(errs), 1)[0])
    ctx.check_abs("contact-time convergence order in dt (velocity Verlet)", order, 2.0, 0.3,
                  note=f"dt = {', '.join(f'{d:g}' for d in dts)} s; errors {', '.join(f'{e:.2e}' for e in errs)}")
    ax.loglog(walls, errs, "o-")
    for d, w, e in zip(dts, walls, errs):
        ax.annotate(f"dt={d:g}", (w, e), fontsize=8)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("contact-time relative error")
    ax.set_title("speed against error (elastic wall impact)")


def _variant(ctx, kind, e, mode):
    from coupler.scene import load_scene
    return load_scene(ctx.case_dir / f"{kind}.toml",
                      overrides={"contacts[0].restitution": e, "contacts[0].damping": mode,
                                 "output": {"bodies": True, "contacts": False, "energy": False},
                                 "time.output_interval": 1e-6},
                      name=f"{kind}_e{e}_{mode}")


def _restitution(res, kind):
    if kind == "wall":
        return restitution_wall(res.body("ball"))
    return restitution_pair(res.body("a"), res.body("b"))
