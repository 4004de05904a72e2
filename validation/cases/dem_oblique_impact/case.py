"""Oblique sphere-wall impact in gross sliding (v_t = 3 m/s > 7/2 mu (1+e) v_n = 1.89 m/s), e = 0.8, mu = 0.3.
Analytic (Coulomb sliding through the whole contact): tangential impulse J_t = mu (1+e) m v_n and exit spin
omega = J_t R / (2/5 m R^2), within 2 %. The tangential dashpot acts while the spring is below the Coulomb limit
(as in LIGGGHTS and YADE, notes P9/P17), which makes the impulse exceed the Coulomb value by < 1 %.
A sweep of v_t/v_n shows the transition from sticking to gross sliding (plot). Radius, mass, v_n, mu and e are read
from the scene file."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.analytic import sliding_impact
from validation.metrics import scene_sphere_props, tangential_impulse

TITLE = "Oblique sphere-wall impact: tangential impulse and spin (gross sliding)"
FULL_ONLY = False
RTOL = 0.02


def evaluate(ctx):
    scene = ctx.scene("wall.toml")
    ball = scene_sphere_props(scene, "ball")
    m, radius, vn = ball["mass"], ball["radius"], -float(ball["velocity"][1])
    law = scene.contact_law(ball["material"].name, scene.dem.planes[0].material)
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    b = res.body("ball")
    ref = sliding_impact(law.friction, law.restitution, m, vn, radius)
    jt = tangential_impulse(b, m)
    ctx.check_rel("tangential impulse [N s]", float(jt), ref["tangential_impulse"], RTOL, wall_time_s=wall)
    ctx.check_rel("exit spin |w_z| [rad/s]", float(abs(b["wz"].iloc[-1])), ref["exit_spin"], RTOL, wall_time_s=wall)

    # sweep over the impact angle: normalised tangential impulse vs v_t / v_n (Maw et al. 1976 regimes)
    ratios = np.array([0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0])
    jn = []
    for r in ratios:
        sc = load_scene(ctx.case_dir / "wall.toml", overrides={"dem.spheres[0].velocity": [float(r) * vn, -vn, 0.0],
                                                               "output.contacts": False}, name=f"oblique_{r}")
        rr = ctx.run(sc, tag=f"oblique_{r}")
        bb = rr.body("ball")
        jn.append(tangential_impulse(bb, m) / (law.friction * (1 + law.restitution) * m * vn))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    c = res.contacts
    ax1.plot(c["t"] * 1e6, c["ft"], label="|F_t| native")
    ax1.plot(c["t"] * 1e6, law.friction * c["fn"], "--", label="mu F_n")
    ax1.set_xlabel("t [µs]")
    ax1.set_ylabel("force [N]")
    ax1.set_title(f"v_t = {float(ball['velocity'][0]):g} m/s, v_n = {vn:g} m/s")
    ax1.legend()
    ax2.plot(ratios, jn, "o-", label="native")
    ax2.plot(ratios, np.minimum(1.0, ratios / (3.5 * law.friction * (1 + law.restitution))), "k:",
             label="rigid-body limit min(1, v_t / (7/2 mu (1+e) v_n))")
    ax2.set_xlabel("v_t / v_n")
    ax2.set_ylabel("J_t / (mu (1+e) m v_n)")
    ax2.legend()
    ctx.save_plot(fig)
