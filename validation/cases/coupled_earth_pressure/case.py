"""Earth pressure on a smooth DEM wall block: dry cohesionless Mohr-Coulomb backfill (phi = 30 deg, psi = 0,
geostatic initial stress with k0 from the scene), held wall until t_hold, then moved away at a prescribed speed.
  * at rest (mean over the last 0.05 s of the hold): thrust per unit depth = 1/2 K0 gamma H^2 (3 %);
  * active (mean over the last 0.1 s): 1/2 Ka gamma H^2, Ka = (1 - sin phi)/(1 + sin phi) (10 %);
  * the interface force balance and the interface work of each side; plot: thrust vs wall displacement / H.
Thrust = the x force the wall spheres put on the interface wall / thickness (interface.csv fx_dem)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.cases.coupled_common.balance import interface_balance, plot_interface, read_log

TITLE = "Coupled earth pressure: MC backfill on a held, then retreating, smooth DEM wall (K0, Rankine active)"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("scene.toml")
    tag = "coupled"
    res = ctx.run(scene, tag=tag)
    wall = ctx.wall_times[tag]
    body = scene.mpm.bodies[0]
    rho = scene.materials[body.material].density
    g = -float(scene.gravity[1])
    H = float(body.polygon[:, 1].max() - body.polygon[:, 1].min())
    phi = math.radians(body.model.friction_angle)
    k0 = float(body.k0)
    ka = (1 - math.sin(phi)) / (1 + math.sin(phi))
    th = scene.coupling.thickness
    it = res.interface
    T = it["fx_dem"].to_numpy() / th
    t = it["t"].to_numpy()
    hold, move = scene.coupling.motions[0], scene.coupling.motions[1]
    t_end = t[-1]
    rest = (t > hold.until - 0.05) & (t <= hold.until)
    act = t > t_end - 0.1
    ref0 = 0.5 * k0 * rho * g * H ** 2
    refa = 0.5 * ka * rho * g * H ** 2
    ctx.check_rel("at-rest thrust per unit depth [N/m]", float(T[rest].mean()), ref0, 0.03, wall_time_s=wall,
                  note=f"1/2 K0 gamma H^2, K0 = {k0:g} (initial stress), H = {H:g} m")
    disp = np.where(t > move.start, -move.velocity[0] * (t - move.start), 0.0)
    ctx.check_rel("active thrust per unit depth [N/m]", float(T[act].mean()), refa, 0.10, wall_time_s=wall,
                  note=f"1/2 Ka gamma H^2, Ka = {ka:.4f}; wall displacement at the end {disp[-1] / H:.4f} H")
    interface_balance(ctx, res, tag, wall)

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.2))
    plot_interface(a1, a2, res, read_log(ctx, tag))
    a3.plot(disp / H * 100, T, lw=0.8, label="coupled (per coupling step)")
    a3.axhline(ref0, color="b", ls=":", label="1/2 K0 gamma H^2")
    a3.axhline(refa, color="r", ls=":", label="1/2 Ka gamma H^2 (Rankine)")
    a3.set_ylim(0, 1.5 * ref0)
    a3.set_xlabel("wall displacement / H [%]"); a3.set_ylabel("thrust [N/m]"); a3.legend(fontsize=8)
    fig.tight_layout()
    ctx.save_plot(fig)
