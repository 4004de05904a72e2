"""Sub-cycling sweep: the DEM step fixed, the coupling (= MPM) step = ratio x DEM step, for the free collision
(coupled_free_collision/scene.toml) and the earth pressure at rest (coupled_earth_pressure/scene.toml, hold phase
only). Ratio from 1 to the largest the MPM allows (its cfl = 1 limit; the collision also stays below the
staggering's own limit). Errors vs ratio and wall time vs ratio are plotted; the rows check what the two cases
check (collision: momentum 1e-6, energy 1 %; earth pressure: at-rest thrust 3 %) at every ratio.
Measured (2026-12-01): collision energy closure 0.14 % (ratio 1), 0.24, 0.51, 0.89 (10), 1.47 (20), 2.09 % (40):
first order in the coupling step, so ratios 20 and 40 (coupling step >= 3e-4 s) FAIL the 1 % closure; momentum is
exact (1e-11) at every ratio; the at-rest thrust is -1.3 to -1.4 % at every ratio (the wall-contact compliance)."""
from __future__ import annotations

import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.framework import CASES_DIR

TITLE = "Coupled sub-cycling sweep: error and wall time vs the MPM/DEM step ratio"
FULL_ONLY = False

COLLISION_DEM_DT = 1.5e-5
COLLISION_RATIOS = (1, 2, 5, 10, 20, 40)
EARTH_DEM_DT = 1.0e-5
EARTH_RATIOS = (2, 5, 10, 20)      # ratio 1 (20,000 MPM steps, ~60 s) left out for the wall time


def evaluate(ctx):
    import pandas as pd
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.2))
    rows = []
    src = CASES_DIR / "coupled_free_collision" / "scene.toml"
    for n in COLLISION_RATIOS:
        scene = load_scene(src, overrides={"coupling.dt": n * COLLISION_DEM_DT, "coupling.dem_substeps": n},
                           name=f"collision_r{n}")
        tag = f"collision_r{n}"
        res = ctx.run(scene, tag=tag)
        wall = ctx.wall_times[tag]
        log = pd.read_csv(ctx.out_dir / tag / "coupling_log.csv")
        Px = (log.px_dem + log.px_mpm).to_numpy()
        E = (log.K_dem + log.E_dem + log.D_dem + log.K_mpm + log.E_mpm).to_numpy()
        dP = float(np.abs(Px - Px[0]).max() / abs(Px[0]))
        dE = float(np.abs(E - E[0]).max() / E[0])
        ctx.check_max(f"collision ratio {n}: momentum drift [-]", dP, 1e-6, wall_time_s=wall)
        ctx.check_max(f"collision ratio {n}: energy closure max |E - K0|/K0 [-]", dE, 1e-2, wall_time_s=wall,
                      note=f"coupling step {n * COLLISION_DEM_DT:.3g} s; the weak scheme's energy error is first "
                           f"order in the coupling step (the wall moves with the MPM velocity of the step start)")
        rows.append(("collision", n, dE, wall))
    src = CASES_DIR / "coupled_earth_pressure" / "scene.toml"
    for n in EARTH_RATIOS:
        base = load_scene(src)
        t_hold = base.coupling.motions[0].until
        scene = load_scene(src, overrides={"coupling.dt": n * EARTH_DEM_DT, "coupling.dem_substeps": n,
                                           "time.t_end": t_hold, "time.output_interval": t_hold},
                           name=f"earth_rest_r{n}")
        tag = f"earth_r{n}"
        res = ctx.run(scene, tag=tag)
        wall = ctx.wall_times[tag]
        body = scene.mpm.bodies[0]
        H = float(body.polygon[:, 1].max())
        ref = 0.5 * body.k0 * scene.materials[body.material].density * -scene.gravity[1] * H ** 2
        it = res.interface
        T = float(it.loc[it.t > t_hold - 0.05, "fx_dem"].mean()) / scene.coupling.thickness
        ctx.check_rel(f"earth pressure ratio {n}: at-rest thrust [N/m]", T, ref, 0.03, wall_time_s=wall,
                      note=f"coupling step {n * EARTH_DEM_DT:.3g} s")
        rows.append(("earth", n, abs(T - ref) / ref, wall))
    for case, mk in (("collision", "o-"), ("earth", "s-")):
        r = [x for x in rows if x[0] == case]
        a1.plot([x[1] for x in r], [x[2] * 100 for x in r], mk, label=case)
        a2.plot([x[1] for x in r], [x[3] for x in r], mk, label=case)
    a1.set_xscale("log"); a1.set_xlabel("MPM step / DEM step"); a1.set_ylabel("error [%]"); a1.legend()
    a1.set_title("collision: max energy closure; earth: at-rest thrust")
    a2.set_xscale("log"); a2.set_xlabel("MPM step / DEM step"); a2.set_ylabel("wall time [s]"); a2.legend()
    a3.axis("off")
    a3.text(0.0, 0.5, "\n".join(f"{c} ratio {n}: error {e * 100:.3f} %, wall {w:.1f} s" for c, n, e, w in rows),
            fontsize=8, va="center")
    fig.tight_layout()
    ctx.save_plot(fig)
