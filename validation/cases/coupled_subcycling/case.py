"""Sub-cycling sweep: the DEM step fixed, the coupling (= MPM) step = ratio x DEM step, for the free collision
(coupled_free_collision/scene.toml) and the earth pressure at rest (coupled_earth_pressure/scene.toml, hold phase
only). Ratio from 1 to the largest the MPM allows (its cfl = 1 limit, ratio 45 for the collision). Growing the
ratio therefore grows the coupling step: with the coupling step fixed and the DEM step shrunk (1, 10, 100
sub-steps, coupled_free_collision) the closure does not change (0.89 % each).

Rows (the issue's criteria): momentum of both partitions at every ratio (1e-6); the 1 % energy closure of the
free collision where the issue sets it, i.e. at coupling steps up to the free collision's own (1.5e-4 s: ratios
1-10); the interface force balance of every run (1e-9); the at-rest thrust at every ratio (3 %); and the order of
the energy error in the coupling step (log-log slope of the DEM-side part, the weak scheme's wall lag: 1 +- 0.2).
The closure at ratios 20 and 40 (coupling steps 3e-4 and 6e-4 s) is a measured quantity with its trend (notes
and plot), not a pass/fail row: it exceeds 1 % (1.5 and 2.1 %) as the first-order error predicts.

Energy split, at every output time, relative to K0 (interface.csv work columns, coupling_log.csv energies):
  DEM side  = dE_dem + W_dem   (W_dem: work of the spheres on the moving wall). The wall moves in a step with
              the MPM interface velocity of the step start and then jumps to the MPM position (O(dt^2) per step):
              the contact dashpot never sees the jump, so this part is first order in the coupling step even
              with the DEM step fixed (-0.08 % x ratio measured). The linear velocity predictor
              (`[coupling] predictor = "linear"`) removes most of it (run at ratio 10, note) but is unstable at
              the largest ratios, so the default stays "constant".
  MPM side  = dE_mpm - W_mpm   (W_mpm: work of the point loads on the boundary-particle displacement): the explicit
              MPM's own energy error under the contact load, first order in its step.
  interface = W_mpm - W_dem    (what the MPM received minus what the DEM gave): second order in the coupling
              step (5e-6 K0 at ratio 1, 8e-3 K0 at ratio 40)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene
from validation.cases.coupled_common.balance import interface_balance, plot_interface, read_log
from validation.framework import CASES_DIR

TITLE = "Coupled sub-cycling sweep: error and wall time vs the MPM/DEM step ratio (energy split, order)"
FULL_ONLY = False

COLLISION_DEM_DT = 1.5e-5
COLLISION_RATIOS = (1, 2, 5, 10, 20, 40)
COLLISION_DT_FREE = 1.5e-4       # the coupling step of coupled_free_collision (where the issue sets the 1 %)
EARTH_DEM_DT = 1.0e-5
EARTH_RATIOS = (2, 5, 10, 20)      # ratio 1 (20,000 MPM steps, ~60 s) left out for the wall time


def energy_split(log, it) -> dict:
    """Per output time, relative to the initial total energy: total, DEM side, MPM side, interface mismatch."""
    k = np.searchsorted(it["t"].to_numpy(), log["t"].to_numpy() - 1e-12)
    wd = it["work_dem"].to_numpy()[k]
    wm = it["work_mpm"].to_numpy()[k]
    Ed = (log.K_dem + log.E_dem + log.D_dem).to_numpy()
    Em = (log.K_mpm + log.E_mpm).to_numpy()
    E0 = Ed[0] + Em[0]
    return {"t": log["t"].to_numpy(), "total": (Ed + Em - E0) / E0, "dem": (Ed - Ed[0] + wd) / E0,
            "mpm": (Em - Em[0] - wm) / E0, "interface": (wm - wd) / E0}


def _collision(n, predictor="constant"):
    """The free collision at DEM/MPM step ratio n: (scene, tag)."""
    src = CASES_DIR / "coupled_free_collision" / "scene.toml"
    ov = {"coupling.dt": n * COLLISION_DEM_DT, "coupling.dem_substeps": n}
    tag = f"collision_r{n}"
    if predictor != "constant":
        ov["coupling.predictor"] = predictor
        tag += f"_{predictor}"
    return load_scene(src, overrides=ov, name=tag), tag


def _earth(n):
    """The earth pressure at rest at DEM/MPM step ratio n: (scene, tag)."""
    src = CASES_DIR / "coupled_earth_pressure" / "scene.toml"
    t_hold = load_scene(src).coupling.motions[0].until
    scene = load_scene(src, overrides={"coupling.dt": n * EARTH_DEM_DT, "coupling.dem_substeps": n,
                                       "time.t_end": t_hold, "time.output_interval": t_hold},
                       name=f"earth_rest_r{n}")
    return scene, f"earth_r{n}"


def evaluate(ctx):
    fig, ax = plt.subplots(2, 3, figsize=(16, 8.4))
    (a1, a2, a3), (b1, b2, b3) = ax
    rows, split, runs = [], {}, {}
    # every run of the sweep is independent: one batch (dask tasks under validate --workers, else serial)
    jobs = [_collision(n) for n in COLLISION_RATIOS] + [_collision(10, "linear")] + [_earth(n) for n in EARTH_RATIOS]
    done = dict(zip([tag for _, tag in jobs], ctx.run_many(jobs)))
    for n in COLLISION_RATIOS:
        tag = f"collision_r{n}"
        res, log = done[tag], read_log(ctx, tag)
        runs[n] = (res, log)
        wall = ctx.wall_times[tag]
        Px = (log.px_dem + log.px_mpm).to_numpy()
        dP = float(np.abs(Px - Px[0]).max() / abs(Px[0]))
        sp = split[n] = energy_split(log, res.interface)
        dE = float(np.abs(sp["total"]).max())
        dt = n * COLLISION_DEM_DT
        ctx.check_max(f"collision ratio {n}: momentum drift [-]", dP, 1e-6, wall_time_s=wall)
        parts = (f"DEM side {np.abs(sp['dem']).max() * 100:.3f} %, MPM side {np.abs(sp['mpm']).max() * 100:.3f} %, "
                 f"interface work mismatch {np.abs(sp['interface']).max() * 100:.4f} % (max |.| over the run)")
        if dt <= COLLISION_DT_FREE * (1 + 1e-9):
            ctx.check_max(f"collision ratio {n}: energy closure max |E - K0|/K0 [-]", dE, 1e-2, wall_time_s=wall,
                          note=f"coupling step {dt:.3g} s; {parts}")
        else:
            ctx.notes.append(f"collision ratio {n} (coupling step {dt:.3g} s, beyond the free collision's "
                             f"{COLLISION_DT_FREE:g} s where the issue sets 1 %): energy closure {dE * 100:.2f} % "
                             f"measured, not a pass/fail row; {parts}")
        interface_balance(ctx, res, tag, wall, label=f"collision ratio {n}")
        rows.append(("collision", n, dE, wall))
    # the order of the energy error in the coupling step: log-log slope (least squares over all ratios)
    dts = np.array(COLLISION_RATIOS) * COLLISION_DEM_DT
    slopes = {}
    for part in ("total", "dem", "mpm"):
        err = np.array([np.abs(split[n][part]).max() for n in COLLISION_RATIOS])
        slopes[part] = float(np.polyfit(np.log(dts), np.log(err), 1)[0])
    ctx.check_abs("collision: order of the DEM-side energy error in the coupling step (log-log slope) [-]",
                  slopes["dem"], 1.0, 0.2,
                  note=f"the weak scheme's wall lag; slopes of the total closure {slopes['total']:.2f}, of the "
                       f"MPM side {slopes['mpm']:.2f} (ratios {COLLISION_RATIOS[0]}-{COLLISION_RATIOS[-1]})")
    ctx.notes.append("energy closure (max |E - K0|/K0) against the coupling step: "
                     + ", ".join(f"ratio {n}: {np.abs(split[n]['total']).max() * 100:.2f} %" for n in COLLISION_RATIOS)
                     + f"; log-log slope {slopes['total']:.2f} (first order; the DEM side alone "
                       f"{slopes['dem']:.2f}, the MPM side {slopes['mpm']:.2f})")
    # evidence for the DEM-side origin: the same run with the linear velocity predictor
    tag_p = "collision_r10_linear"
    res_p, log_p = done[tag_p], read_log(ctx, tag_p)
    sp = energy_split(log_p, res_p.interface)
    ctx.notes.append(f"ratio 10 with predictor = \"linear\" (wall velocity 2 v_n - v_(n-1)): DEM side "
                     f"{np.abs(sp['dem']).max() * 100:.3f} % (constant: {np.abs(split[10]['dem']).max() * 100:.3f} %), "
                     f"MPM side {np.abs(sp['mpm']).max() * 100:.3f} %, total closure "
                     f"{np.abs(sp['total']).max() * 100:.3f} % (constant: {np.abs(split[10]['total']).max() * 100:.3f} %): "
                     f"the predictor removes the wall lag, the explicit MPM's own error of the same order remains; "
                     f"at ratio 40 the extrapolation is unstable, so it is not the default")

    for n in EARTH_RATIOS:
        scene, tag = _earth(n)
        t_hold = scene.time.t_end
        res = done[tag]
        wall = ctx.wall_times[tag]
        body = scene.mpm.bodies[0]
        H = float(body.polygon[:, 1].max())
        ref = 0.5 * body.k0 * scene.materials[body.material].density * -scene.gravity[1] * H ** 2
        it = res.interface
        T = float(it.loc[it.t > t_hold - 0.05, "fx_dem"].mean()) / scene.coupling.thickness
        ctx.check_rel(f"earth pressure ratio {n}: at-rest thrust [N/m]", T, ref, 0.03, wall_time_s=wall,
                      note=f"coupling step {n * EARTH_DEM_DT:.3g} s")
        interface_balance(ctx, res, tag, wall, label=f"earth pressure ratio {n}")
        rows.append(("earth", n, abs(T - ref) / ref, wall))

    # plots: energy error split against the coupling step (log-log, slope 1 for reference), thrust error, wall time
    for part, mk in (("total", "o-"), ("dem", "s--"), ("mpm", "^--"), ("interface", "x:")):
        a1.loglog(dts, [max(np.abs(split[n][part]).max(), 1e-12) * 100 for n in COLLISION_RATIOS], mk,
                  label={"total": "total closure", "dem": "DEM side (wall lag)", "mpm": "MPM side (explicit MPM)",
                         "interface": "interface work mismatch"}[part])
    a1.loglog(dts, np.abs(split[1]["total"]).max() * 100 * dts / dts[0], "k:", lw=0.8, label="slope 1")
    a1.axhline(1.0, color="r", ls=":", lw=0.8)
    a1.axvline(COLLISION_DT_FREE, color="gray", ls=":", lw=0.8)
    a1.set_xlabel("coupling (= MPM) step [s]  (ratio x 1.5e-5 s)"); a1.set_ylabel("max |.| / K0 [%]")
    a1.set_title("collision: energy error split"); a1.legend(fontsize=7)
    r = [x for x in rows if x[0] == "earth"]
    a2.plot([x[1] for x in r], [x[2] * 100 for x in r], "s-", label="earth pressure: at-rest thrust")
    a2.axhline(3.0, color="r", ls=":", lw=0.8)
    a2.set_xscale("log"); a2.set_xlabel("MPM step / DEM step"); a2.set_ylabel("|error| [%]"); a2.legend(fontsize=8)
    for case, mk in (("collision", "o-"), ("earth", "s-")):
        r = [x for x in rows if x[0] == case]
        a3.plot([x[1] for x in r], [x[3] for x in r], mk, label=case)
    a3.set_xscale("log"); a3.set_xlabel("MPM step / DEM step"); a3.set_ylabel("wall time [s]"); a3.legend()
    n_last = COLLISION_RATIOS[-1]
    plot_interface(b1, b2, *runs[n_last], label=f"ratio {n_last}:")
    for n, c in ((10, "C0"), (n_last, "C3")):
        sp = split[n]
        b3.plot(sp["t"], sp["total"] * 100, "-", color=c, label=f"ratio {n} total")
        b3.plot(sp["t"], sp["dem"] * 100, "--", color=c, label=f"ratio {n} DEM side")
        b3.plot(sp["t"], sp["mpm"] * 100, ":", color=c, label=f"ratio {n} MPM side")
    b3.set_xlabel("t [s]"); b3.set_ylabel("energy error / K0 [%]"); b3.legend(fontsize=7)
    from matplotlib.ticker import NullFormatter
    for a in (a1, a2, a3):              # log axes: label the decades only (the minor labels overlap)
        a.xaxis.set_minor_formatter(NullFormatter())
    fig.tight_layout()
    ctx.save_plot(fig)
