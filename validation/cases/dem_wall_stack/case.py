"""Six-block wall under gravity for 1 s (issue #4). wall.toml is the Bui 2014 geometry: blocks 3.2 cm x 2.5 cm
(6 x 5 glued spheres), each course 1.2 cm behind the one below. Without its backfill that wall cannot stand:
the combined centre of mass of courses 2-6 lies 3.6 cm behind the centre of course 1, outside its 1.6 cm
half-width, so statics predicts toppling; the case checks that the DEM topples it (a rotation above 10 deg).
The same six blocks stacked vertically (setback 0, a variant of the same scene file) must stand: every centroid
drifts less than 0.1 mm after the first 0.05 s of contact settling."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.metrics import rotation_z_deg

TITLE = "Rigid clusters: six-block stacked wall (vertical stands; Bui setback topples without backfill)"
FULL_ONLY = False
SETTLE = 0.05


def _drift_and_rotation(res):
    worst, rot, series = 0.0, 0.0, []
    for k in range(1, 7):
        b = res.body(f"block{k}")
        t = b["t"].to_numpy()
        x, y = b["x"].to_numpy(), b["y"].to_numpy()
        i0 = int(np.argmin(abs(t - SETTLE)))
        d = np.hypot(x - x[i0], y - y[i0])
        worst = max(worst, float(d[i0:].max()))
        rot = max(rot, float(np.abs(rotation_z_deg(b)).max()))
        series.append((t, d))
    return worst, rot, series


def evaluate(ctx):
    base = ctx.scene("wall.toml")
    vertical = load_scene(ctx.case_dir / "wall.toml", name="wall_stack_vertical",
                          overrides={f"dem.clusters[{k}].position": [0.1, float(base.dem.clusters[k].position[1]), 0.0]
                                     for k in range(6)})
    res_v = ctx.run(vertical, tag="vertical")
    drift, rot, series = _drift_and_rotation(res_v)
    ctx.check_max("vertical stack: largest centroid drift after settling [m]", drift, 1e-4,
                  wall_time_s=ctx.wall_times["vertical"], note=f"largest rotation {rot:.2e} deg")
    res_s = ctx.run(base, tag="setback")
    _, rot_s, _ = _drift_and_rotation(res_s)
    ctx.check_abs("setback wall without backfill topples (1 = rotation > 10 deg)", float(rot_s > 10.0), 1.0, 0.0,
                  wall_time_s=ctx.wall_times["setback"], note=f"largest rotation {rot_s:.1f} deg; statics: topples")
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, (t, d) in enumerate(series):
        ax.plot(t, d * 1e3, label=f"block {k + 1}")
    ax.axhline(0.1, color="k", ls=":")
    ax.set(xlabel="t [s]", ylabel="centroid displacement from t = 0.05 s [mm]", title="vertical six-block stack")
    ax.legend(fontsize=8)
    ctx.save_plot(fig)
