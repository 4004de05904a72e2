"""Block slide (issue #4): a 6 x 5 block of glued 5 mm Al spheres (exact mass properties), planar, sliding on a
plane, v0 = 0.3 m/s, mu = 0.3, e = 0.8. Analytic stop distance v0^2 / (2 mu g) within 1 %; the energy balance
(K + P + E_el + D) is shown."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.analytic import slide_stop_distance

TITLE = "Rigid cluster: block slide vs v0^2/(2 mu g)"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("block.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    b = res.body("block")
    g = float(np.linalg.norm(scene.gravity))
    ref = slide_stop_distance(0.3, 0.3, g)
    ctx.check_rel("stop distance [m]", float(b["x"].iloc[-1] - b["x"].iloc[0]), ref, 0.01, wall_time_s=wall)
    t = b["t"].to_numpy()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4))
    a1.plot(t, b["x"] - b["x"].iloc[0], label="native")
    ts = np.linspace(0, 0.3 / (0.3 * g), 100)
    a1.plot(ts, 0.3 * ts - 0.5 * 0.3 * g * ts ** 2, "k:", label="analytic")
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
