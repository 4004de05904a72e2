"""Hard case, coupled (issue #17): a stiff DEM block on a soft MPM body, stiffness ratio 1e4 (scene.toml: the
coupled_resting_load block and soil with E = 1e10 Pa for the steel block and the interface-wall material against
E = 1e6 Pa for the MPM soil), 0.2 s. The automatic DEM step (1.66e-5 s, the stiff steel contact) is 24x below the
MPM's CFL step (cfl 0.5); the automatic coupling step (coupler/coupling/step_limit.py: the interface contact's
Hertz time / 10 with the mass of an MPM surface node) is 0.94 DEM step.

Runs and rows:
  * without sub-cycling: coupling (= MPM) step = the DEM step (ratio 1);
  * with sub-cycling: coupling step = the largest stable ratio of the sweep x the DEM step, that many DEM sub-steps;
  * automatic: the scene as written (coupling step and dem_substeps "auto");
  each: the vertical load the MPM receives per unit depth, mean over the last 0.05 s, against the block weight
  M g / thickness (1 %: coupled_resting_load asks 0.1 % after 0.6 s; this run is 0.2 s long, in which the damped
  MPM block's residual oscillation of ~4 % of the load at 0.1 s (ratio 1) has decayed to well under 1 %); and the
  sub-cycled mean settlement under the block against the unsub-cycled one (1 %).
  * sweep: the DEM step fixed, the coupling step = ratio x DEM step, ratios from 1 to the MPM's cfl = 1 limit.
    A ratio is stable when the run finishes and, over its last 0.05 s, the load is within 1 % of M g / thickness
    and its standard deviation below 10 % of it (an unstable staggered contact chatters: the block bounces on
    the MPM nodes with a force many times its weight). Row: the automatic ratio against the largest stable one
    (auto / largest stable <= 1). The note gives the linear estimate of the limit: the stiff contact acts on a
    boundary node of the MPM as an explicit spring k (static Hertz stiffness of one sphere's contact / thickness)
    on the node mass m (rho h^2 / 2 per unit depth), stable for coupling step < 2 sqrt(m / k).
    Row: the automatic coupling step against the largest stable one of the sweep (<= 1).
Before the interface limit (issue 17), "auto" kept the MPM's CFL step and sub-cycled the DEM 24 times: unstable
(the block chattered on the MPM nodes)."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.dem.timestep import chosen_dt
from coupler.errors import SimulationError
from coupler.scene import load_scene
from validation.cases.coupled_common.balance import read_points

TITLE = "Hard case, coupled: stiff DEM block on a soft MPM body (1e4), with / without sub-cycling, step-ratio sweep"
FULL_ONLY = False
LAST = 0.05                      # s: the window of the load mean and spread
RATIOS = (1, 2, 4, 6, 8, 12, 16, 24, 32, 46)


def _block_weight(scene) -> tuple[float, float]:
    tpl = scene.dem.templates["bar"]
    m = scene.materials["steel"].density * 4.0 / 3.0 * np.pi * tpl.radii ** 3
    return float(m.sum() * -scene.gravity[1] / scene.coupling.thickness), float(m[0] * -scene.gravity[1])


def _run(ctx, ratio: int | None, dem_dt: float):
    """(result or None, error message, tag) of the scene at a DEM/MPM step ratio (None: the scene as written)."""
    tag = "auto" if ratio is None else f"ratio_{ratio}"
    ov = {} if ratio is None else {"coupling.dt": ratio * dem_dt, "coupling.dem_substeps": ratio}
    scene = load_scene(ctx.case_dir / "scene.toml", overrides=ov, name=f"hard_stiff_on_soft_{tag}")
    try:
        return ctx.run(scene, tag=tag), "", tag
    except SimulationError as e:
        return None, str(e), tag


def _load(res, w: float) -> tuple[float, float]:
    it = res.interface
    late = it["t"] > it["t"].iloc[-1] - LAST
    thickness_force = -it.loc[late, "fy_mpm"]
    return float(thickness_force.mean()), float(thickness_force.std())


def evaluate(ctx):
    scene = ctx.scene("scene.toml")
    th = scene.coupling.thickness
    w, w_sphere = _block_weight(scene)
    dem_dt = chosen_dt(scene)
    runs = {}
    for ratio in RATIOS:
        runs[ratio] = _run(ctx, ratio, dem_dt)
    auto = _run(ctx, None, dem_dt)
    from coupler.coupling.solver import CoupledRun
    cr = CoupledRun(load_scene(ctx.case_dir / "scene.toml"))
    auto_ratio = cr.dt / dem_dt                 # automatic coupling step in DEM steps (of the sweep's DEM step)
    ctx.notes.append(f"automatic coupling step {cr.dt:.4g} s ({auto_ratio:.3g} DEM steps of {dem_dt:.4g} s), "
                     f"{cr.substeps} DEM sub-step(s) of {cr.dt / cr.substeps:.4g} s: {cr.dt_limit or 'MPM CFL'}")
    stable, err_mean, spread = {}, {}, {}
    for ratio, (res, err, tag) in runs.items():
        if res is None:
            stable[ratio], err_mean[ratio], spread[ratio] = False, math.nan, math.nan
            ctx.notes.append(f"ratio {ratio}: {err}")
            continue
        mean, std = _load(res, w)
        err_mean[ratio] = abs(mean / th / w - 1.0)
        spread[ratio] = std / th / w
        stable[ratio] = err_mean[ratio] <= 0.01 and spread[ratio] <= 0.1
    ok = [r for r in RATIOS if stable[r]]
    largest = max(ok) if ok else 0
    sub = max([r for r in ok if r > 1], default=2)    # the sub-cycled row: the largest stable ratio > 1
    # rows: without sub-cycling (ratio 1), sub-cycled, automatic
    settle = {}
    for label, (res, err, tag) in (("without sub-cycling (ratio 1)", runs[1]),
                                   (f"with sub-cycling (ratio {sub})", runs[sub]),
                                   (f"automatic step ({auto_ratio:.3g} DEM steps, {cr.substeps} sub-step(s))", auto)):
        if res is None:
            ctx.fail(f"{label}: load per unit depth [N/m]", f"blow-up: {err}")
            continue
        mean, std = _load(res, w)
        ctx.check_rel(f"{label}: load per unit depth [N/m]", mean / th, w, 1e-2, wall_time_s=ctx.wall_times[tag],
                      note=f"mean over the last {LAST} s; spread (std) {std / th / w * 100:.3g} % of M g / thickness")
        pts = read_points(ctx, tag)
        xc = float(scene.dem.clusters[0].position[0])
        tpl = scene.dem.templates["bar"]
        half = 0.5 * (tpl.offsets[:, 0].max() - tpl.offsets[:, 0].min()) + tpl.radii.max()
        under = np.abs(pts["x0"].to_numpy() - xc) <= half
        settle[label] = -float(pts["uy"].to_numpy()[under].mean())
    ref = settle.get("without sub-cycling (ratio 1)")
    for label, val in settle.items():
        if ref is not None and not label.startswith("without"):
            tag = runs[sub][2] if label.startswith("with sub") else auto[2]
            ctx.check_rel(f"mean settlement under the block, {label} vs without sub-cycling [m]", val, ref, 1e-2,
                          wall_time_s=ctx.wall_times[tag], note="reference: the run without sub-cycling")
    first_bad = min([r for r in RATIOS if not stable[r]], default=None)
    # linear estimate: static Hertz stiffness of one sphere's contact with the wall, per unit depth, on a node
    steel, wall = scene.materials["steel"], scene.materials[scene.coupling.material]
    estar = 1.0 / ((1 - steel.poisson ** 2) / steel.young + (1 - wall.poisson ** 2) / wall.young)
    r = float(scene.dem.templates["bar"].radii[0])
    delta = (3.0 * w_sphere / (4.0 * estar * math.sqrt(r))) ** (2.0 / 3.0)
    k = 2.0 * estar * math.sqrt(r * delta) / th
    h = scene.mpm.cell_size
    m_node = 0.5 * scene.materials["soil"].density * h * h
    ratio_est = 2.0 * math.sqrt(m_node / k) / dem_dt
    ctx.notes.append(f"sweep (DEM step {dem_dt:.4g} s): stable ratios {ok}; first unstable {first_bad}; linear "
                     f"estimate of the limit 2 sqrt(m/k) / dt_DEM = {ratio_est:.3g} (k = {k:.3g} N/m per m depth, "
                     f"m = {m_node:.3g} kg/m)")
    if ok:
        ctx.check_max("automatic coupling step / largest stable coupling step of the sweep", auto_ratio / largest,
                      1.0, reference=float(largest), note=f"auto {auto_ratio:.3g} DEM steps, largest stable {largest}, "
                      f"first unstable {first_bad}, linear estimate {ratio_est:.3g}")
    else:
        ctx.fail("automatic coupling step / largest stable coupling step of the sweep", "no ratio of the sweep is "
                                                                                         "stable")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    rr = np.array(RATIOS, float)
    a1.loglog(rr, [err_mean[r] for r in RATIOS], "o-", label="|mean load / (M g / thickness) - 1|")
    a1.loglog(rr, [spread[r] for r in RATIOS], "s--", label="std of the load / (M g / thickness)")
    for r in RATIOS:
        if not stable[r]:
            a1.axvline(r, color="r", alpha=0.2, lw=6)
    a1.axvline(ratio_est, color="k", ls=":", label=f"linear estimate {ratio_est:.3g}")
    a1.axvline(auto_ratio, color="g", ls="--", label=f"automatic coupling step ({auto_ratio:.3g} DEM steps)")
    a1.axhline(0.01, color="gray", lw=0.8)
    a1.set_xlabel("DEM/MPM step ratio (coupling step / DEM step)")
    a1.set_title(f"step-ratio sweep (red: unstable); largest stable {largest}", fontsize=9)
    a1.legend(fontsize=7)
    for label, (res, _, tag) in (("ratio 1", runs[1]), (f"ratio {sub}", runs[sub]), ("automatic", auto)):
        if res is not None:
            it = res.interface
            a2.plot(it["t"], -it["fy_mpm"] / th / w, lw=0.8, label=label)
    a2.set_xlabel("t [s]")
    a2.set_ylabel("load / (M g / thickness)")
    a2.set_ylim(-1, 10)
    a2.legend(fontsize=8)
    fig.tight_layout()
    ctx.save_plot(fig)
