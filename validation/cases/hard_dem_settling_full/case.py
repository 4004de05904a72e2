"""Hard case, DEM (issue #17), --full only: the dense-pack settling of hard_dem/settling.toml at 50,000 spheres
(the box 0.3 x 0.3 m instead of 0.06 x 0.06 m, the same height and packing density; soft glass-like spheres,
E = 5 MPa, R 1.6-2.4 mm, automatic step 1.44e-5 s: 69,290 steps, ~3.5e9 particle-steps). Run whole on 2026-12-02:
1,312 s wall on one numba thread beside three other jobs on the 2-core machine (2.6e6 particle-steps/s); energy
gain 5.1e-9 of the released potential energy, kinetic energy rise after the impacts 1.2e-6 of its peak: passes. Checks and tolerances as the reduced pack
(validation/cases/hard_common/settling.py): no energy gain (1 % of the released potential energy) and kinetic
energy non-increasing after the initial impacts (1 % of its peak)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from coupler.scene import load_scene
from validation.cases.hard_common.settling import settling_checks
from validation.framework import CASES_DIR

TITLE = "Hard case, DEM: a dense pack of 50,000 spheres settling for 1 s (kinetic energy non-increasing)"
FULL_ONLY = True
WIDTH = 0.3          # m: 25 x the floor area of the 2,000-sphere pack
COUNT = 50_000


def evaluate(ctx):
    scene = load_scene(CASES_DIR / "hard_dem" / "settling.toml", name="hard_settling_50k", overrides={
        "dem.packings[0].count": COUNT, "dem.packings[0].box_max": [WIDTH, 0.16, WIDTH],
        "dem.planes[2].point": [WIDTH, 0.0, 0.0], "dem.planes[4].point": [0.0, 0.0, WIDTH]})
    s = settling_checks(ctx, scene, "settling_50k", "settling (50,000 spheres)")
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.semilogy(s["t"], s["kinetic"], label="kinetic")
    ax.axvline(s["t_star"], color="k", ls=":", label="t* (after the impacts)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("J")
    ax.legend()
    ctx.save_plot(fig)
