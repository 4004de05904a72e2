"""Stability and energy account on a hard case: planar collapse of a polydisperse column of 1,500 frictional
aluminium-like spheres (soft E = 70 MPa for a larger stable step; e = 0.5, mu = 0.4, auto dt) onto a floor
against a back wall, 0.4 s. Checks: the run finishes (no NaN, nobody leaves the domain, no energy jump), the energy
balance K + P + E_el + D = E(0) holds to 1 % of the potential energy released (D accumulated from the contact
work, not as a residual), and D never decreases by more than round-off."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.metrics import total_energy

TITLE = "Hard case: 2D column collapse of 1,500 frictional spheres (stability, energy balance)"
FULL_ONLY = False


def evaluate(ctx):
    scene = ctx.scene("column.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    e = res.energy
    released = float(e["potential"].iloc[0] - e["potential"].min())
    total = total_energy(e)
    ctx.check_max("energy balance error / released potential energy", float(np.abs(total - total[0]).max()) / released,
                  0.01, wall_time_s=wall)
    dd = np.diff(e["dissipated"].to_numpy())
    ctx.check_max("largest decrease of dissipated energy / released", float(max(0.0, -dd.min())) / released, 1e-9,
                  wall_time_s=wall)
    sm = res.summary
    ctx.notes.append(f"speed: {sm['particles'] * sm['steps'] / wall:.3g} particle-steps/s over {sm['steps']} steps, "
                     f"dt {sm['dt']:.3g} s (auto), {sm['neighbour_rebuilds']} neighbour rebuilds, {wall:.1f} s wall")
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.5))
    for col in ("kinetic", "potential", "elastic", "dissipated"):
        ax1.plot(e["t"], e[col], label=col)
    ax1.plot(e["t"], total, "k--", label="sum")
    ax1.set_xlabel("t [s]")
    ax1.set_ylabel("energy [J]")
    ax1.legend()
    b = res.bodies
    for t_show in (0.0, b["t"].max()):
        snap = b[np.isclose(b["t"], t_show)]
        ax2.plot(snap["x"], snap["y"], ".", ms=2, label=f"t = {t_show:.2f} s")
    ax2.set_aspect("equal")
    ax2.legend()
    ctx.save_plot(fig)
