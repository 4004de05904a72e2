"""1D elastic column under gravity (roller walls, fixed base), brought to rest by local damping.
Analytic: sigma_yy(y0) = -rho g (H - y0). Metrics (relative to rho g H):
  * max error of the layer-mean sigma_yy for layers at least one cell above the base (1 %)
  * max error of any single point, full column (1 %)
Shape function uGIMP: with the quadratic B-spline (no boundary-modified splines implemented) the first two cells
above the fixed base are off by up to 30 % (measured), so this case uses GIMP.
  * top displacement vs the oedometric solution rho g H^2 / (2 M) (1 %)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

TITLE = "MPM self-weight column: stress profile vs analytic"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("scene.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    mat = scene.materials["soil"]
    g = -scene.gravity[1]
    H = 1.0
    h = scene.mpm.cell_size
    _, df = res.particles[-1]
    y0 = (df["y"] - df["uy"]).to_numpy()
    ref = -mat.density * g * (H - y0)
    scale = mat.density * g * H
    err = (df["syy"].to_numpy() - ref) / scale
    layers = np.unique(np.round(y0, 9))
    lay_err = np.array([err[np.isclose(y0, yl)].mean() for yl in layers])
    interior = layers > h
    ctx.check_max("layer-mean sigma_yy error, y0 > h [-]", float(np.abs(lay_err[interior]).max()), 0.01,
                  wall_time_s=wall, note="relative to rho g H")
    ctx.check_max("pointwise sigma_yy error, full column [-]", float(np.abs(err).max()), 0.01, wall_time_s=wall,
                  note="all points, uGIMP")
    nu, E = mat.poisson, mat.young
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    u_ref = mat.density * g * H ** 2 / (2 * M)
    ctx.check_rel("top settlement [m]", float(-df["uy"][y0 > H - h].mean()), u_ref, 0.01, wall_time_s=wall,
                  note="oedometric, small strain")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.5))
    a1.plot(df["syy"], y0, ".", ms=2, label="MPM points")
    yy = np.linspace(0, H, 50)
    a1.plot(-mat.density * g * (H - yy), yy, "k-", label="analytic")
    a1.set_xlabel("sigma_yy [Pa]"); a1.set_ylabel("y0 [m]"); a1.legend()
    a2.plot(lay_err * 100, layers, "o-", ms=3)
    a2.axvline(1, color="r", ls=":"); a2.axvline(-1, color="r", ls=":")
    a2.set_xlabel("layer-mean error [% of rho g H]"); a2.set_ylabel("y0 [m]")
    fig.tight_layout()
    ctx.save_plot(fig)
