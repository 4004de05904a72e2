"""Hard case, DEM (issue #17), --full only: the dense-pack settling of hard_dem/settling.toml at 50,000 spheres
(the box 0.3 x 0.3 m instead of 0.06 x 0.06 m, the same height and packing density; soft glass-like spheres,
E = 5 MPa, R 1.6-2.4 mm, automatic step 1.44e-5 s: ~69,000 steps, ~3.5e9 particle-steps). Cost estimate (not yet
run whole): the 2,000-sphere pack took 36 CPU-s for 1.3e8 particle-steps (3.6 M per CPU-second), so ~16 CPU-min
here, ~10 min on two idle cores; generating the 50,000-sphere packing took 22 CPU-s; the first 0.02 s (free fall,
1,386 steps) 2.9 CPU-s. Checks and tolerances as the reduced pack
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
