"""Block slide (issue #4): a 6 x 5 block of glued 5 mm Al spheres (exact mass properties), planar, sliding on a
plane, v0 = 0.3 m/s, mu = 0.3, e = 0.8. Analytic stop distance v0^2 / (2 mu g) within 1 %; the energy balance
(K + P + E_el + D) is shown. v0, mu and g are read from the scene file."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.analytic import slide_stop_distance
from validation.metrics import scene_cluster

TITLE = "Rigid cluster: block slide vs v0^2/(2 mu g)"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("block.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    b = res.body("block")
    g = float(np.linalg.norm(scene.gravity))
    cl, _, mat = scene_cluster(scene, "block")
    v0, mu = float(cl.velocity[0]), scene.contact_law(mat.name, scene.dem.planes[0].material).friction
    ref = slide_stop_distance(v0, mu, g)
    ctx.check_rel("stop distance [m]", float(b["x"].iloc[-1] - b["x"].iloc[0]), ref, 0.01, wall_time_s=wall)
    t = b["t"].to_numpy()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4))
    a1.plot(t, b["x"] - b["x"].iloc[0], label="native")
    ts = np.linspace(0, v0 / (mu * g), 100)
    a1.plot(ts, v0 * ts - 0.5 * mu * g * ts ** 2, "k:", label="analytic")
    a1.set(xlabel="t [s]", ylabel="x - x0 [m]")
    a1.legend()
    e = res.energy
    for col in ("kinetic", "elastic", "dissipated"):
        a2.plot(e["t"], e[col], label=col)
    a2.plot(e["t"], e["kinetic"] + e["elastic"] + e["dissipated"] + e["potential"] - e["potential"].iloc[0], "k--",
            label="sum - P0")
    a2.set(xlabel="t [s]", ylabel="J")
    a2.legend()
    ctx.save_plot(fig)
