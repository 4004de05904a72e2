"""1D elastic column under gravity (roller walls, fixed base), brought to rest by local damping.
Analytic (validation/analytic.py; rho, E, nu, g and the column height H from the scene):
sigma_yy(y0) = -rho g (H - y0). Metrics (relative to rho g H), for uGIMP (scene) and the quadratic
B-spline (boundary-modified at the grid box, coupler/mpm/shapes.py):
  * max error of the layer-mean sigma_yy for layers at least one cell above the base (1 %)
  * max error of any single point, full column (1 %)
  * top displacement vs the oedometric solution rho g H^2 / (2 M) (1 %).
(Before the boundary modification the uniform B-spline was off by up to 30 % in the first two cells above the
base, where its support reaches the ghost nodes below the wall.)"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.analytic import geostatic_stress, oedometric_modulus, self_weight_settlement
from validation.metrics import scene_mpm_body_extent

TITLE = "MPM self-weight column: stress profile vs analytic"
FULL_ONLY = False


def evaluate(ctx):
    base = ctx.scene("scene.toml")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.5))
    for shape in (base.mpm.shape, "bspline2"):
        scene = load_scene(base.source, overrides={"mpm.shape_function": shape})
        res = ctx.run(scene, tag=shape)
        wall = ctx.wall_times[shape]
        mat = scene.materials["soil"]
        g = -scene.gravity[1]
        lo, hi = scene_mpm_body_extent(scene)
        assert lo[1] == 0.0, "column base at y = 0"
        H = float(hi[1])
        h = scene.mpm.cell_size
        _, df = res.particles[-1]
        y0 = (df["y"] - df["uy"]).to_numpy()
        ref = geostatic_stress(mat.density, g, H, y0)
        scale = mat.density * g * H
        err = (df["syy"].to_numpy() - ref) / scale
        layers = np.unique(np.round(y0, 9))
        lay_err = np.array([err[np.isclose(y0, yl)].mean() for yl in layers])
        interior = layers > h
        ctx.check_max(f"{shape}: layer-mean sigma_yy error, y0 > h [-]", float(np.abs(lay_err[interior]).max()),
                      0.01, wall_time_s=wall, note="relative to rho g H")
        ctx.check_max(f"{shape}: pointwise sigma_yy error, full column [-]", float(np.abs(err).max()), 0.01,
                      wall_time_s=wall, note="all points")
        u_ref = self_weight_settlement(mat.density, g, H, oedometric_modulus(mat.young, mat.poisson))
        ctx.check_rel(f"{shape}: top settlement [m]", float(-df["uy"][y0 > H - h].mean()), u_ref, 0.01,
                      wall_time_s=wall, note="oedometric, small strain")
        a1.plot(df["syy"], y0, ".", ms=2, label=f"MPM points, {shape}")
        a2.plot(lay_err * 100, layers, "o-", ms=3, label=shape)
    yy = np.linspace(0, H, 50)
    a1.plot(geostatic_stress(mat.density, g, H, yy), yy, "k-", label="analytic")
    a1.set_xlabel("sigma_yy [Pa]"); a1.set_ylabel("y0 [m]"); a1.legend()
    a2.axvline(1, color="r", ls=":"); a2.axvline(-1, color="r", ls=":")
    a2.set_xlabel("layer-mean error [% of rho g H]"); a2.set_ylabel("y0 [m]"); a2.legend()
    fig.tight_layout()
    ctx.save_plot(fig)
