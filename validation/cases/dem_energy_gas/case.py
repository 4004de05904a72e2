"""Energy conservation: 1,000 elastic (e = 1), frictionless aluminium spheres (R = 2.5 mm, |v0| = 1 m/s in
random directions, seed 7) in a closed 6 cm box without gravity, 0.02 s (about 3 collisions per sphere).
Drift = the linear trend of E = kinetic + potential + elastic over the run, relative to E(0) (< 1e-6).
Max deviation = the largest |E(t) - E(0)| / E(0) at the samples; velocity Verlet keeps it bounded: it is the
O(dt^2) shadow-energy error of contacts in progress, not a drift (stated tolerance 1e-5)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.metrics import total_energy

TITLE = "Energy conservation of a 1,000-sphere elastic gas"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("gas.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    e = res.energy
    t = e["t"].to_numpy()
    total = total_energy(e, dissipated=False)
    rel = (total - total[0]) / total[0]
    slope = np.polyfit(t, rel, 1)[0]
    ctx.check_max("energy drift (trend over run), relative", abs(slope * (t[-1] - t[0])), 1e-6, wall_time_s=wall)
    ctx.check_max("max |E(t) - E(0)| / E(0)", float(np.abs(rel).max()), 1e-5, wall_time_s=wall)
    ctx.check_max("dissipated / E(0)", float(np.abs(e["dissipated"].to_numpy()).max() / total[0]), 1e-5,
                  wall_time_s=wall, note="e = 1, mu = 0: the contact-work account must stay at round-off + O(dt^2)")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(t * 1e3, rel, "o-", ms=3, label="(E - E0)/E0")
    ax.plot(t * 1e3, slope * (t - t[0]), "k--", label="linear trend")
    ax.set_xlabel("t [ms]")
    ax.set_ylabel("relative energy error")
    ax.legend()
    ctx.save_plot(fig)
