"""A DEM block (cluster of 5 spheres, 3D mass M) resting on an elastic MPM block under gravity, weak Gauss-Seidel
coupling through the top side. Checks:
  * the vertical force the MPM receives, per unit depth, is the block weight per unit depth M g / thickness
    (mean over the last 0.1 s; 0.1 %);
  * the mean settlement of the interface points under the block equals that of the same MPM block (same steps,
    same damping) under the same loads applied directly as constant point loads (the mean coupled loads of the
    last output interval; 1 %);
  * the interface force balance (MPM received = DEM on wall, round-off) and the interface work of each side."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from validation.cases.coupled_common.balance import interface_balance, plot_interface, read_log, read_points

TITLE = "Coupled resting load: DEM block on an elastic MPM block (weight per depth, settlement)"
FULL_ONLY = False


def direct_settlement(scene, loads_xy, index, n_steps, dt, n_back=0):
    """The same MPM under constant point loads (N per unit depth) on the interface particles: the interface
    displacement at the end and n_back steps before it (whether the reference is at rest)."""
    from coupler.coupling.partitions import MPMPartition
    mpm = MPMPartition(scene, dt)
    f = np.zeros((mpm.nb, 2))
    f[index] = loads_xy
    mpm.set_point_loads(f)
    u_back = None
    for k in range(n_steps):
        if k == n_steps - n_back:
            u_back = mpm.interface_state()["displacement"][index]
        mpm.advance_to((k + 1) * dt)
    u = mpm.interface_state()["displacement"][index]
    return u, (u if u_back is None else u_back)


def evaluate(ctx):
    scene = ctx.scene("scene.toml")
    tag = "coupled"
    res = ctx.run(scene, tag=tag)
    wall = ctx.wall_times[tag]
    cs = scene.coupling
    th = cs.thickness
    it = res.interface
    # block mass from the scene (exact mass of the non-overlapping members)
    tpl = scene.dem.templates["bar"]
    rho = scene.materials["steel"].density
    M = float(np.sum(rho * 4.0 / 3.0 * np.pi * tpl.radii ** 3))
    g = -float(scene.gravity[1])
    w_ref = M * g / th
    late = it["t"] > it["t"].iloc[-1] - 0.1
    fy = -float(it.loc[late, "fy_mpm"].mean()) / th
    ctx.check_rel("MPM vertical load per unit depth [N/m]", fy, w_ref, 1e-3, wall_time_s=wall,
                  note=f"M g / thickness, M = {M:.5g} kg, thickness {th:g} m; mean over the last 0.1 s")
    bal = interface_balance(ctx, res, tag, wall)

    pts = read_points(ctx, tag)
    n_steps, dt = int(res.summary["steps"]), float(res.summary["dt"])
    from coupler.scene import output_stride
    every = output_stride(scene, dt, "the coupling step")      # steps of the load-averaging window
    u_dir, u_dir_back = direct_settlement(scene, pts[["fx", "fy"]].to_numpy(), cs.geometry.index, n_steps, dt,
                                          every)
    xc = float(scene.dem.clusters[0].position[0])
    half = 0.5 * (tpl.offsets[:, 0].max() - tpl.offsets[:, 0].min()) + tpl.radii.max()
    under = np.abs(pts["x0"].to_numpy() - xc) <= half
    s_c = -float(pts["uy"].to_numpy()[under].mean())
    s_d = -float(u_dir[under, 1].mean())
    ctx.check_rel("mean settlement under the block [m]", s_c, s_d, 1e-2, wall_time_s=wall,
                  note="reference: same MPM, same loads applied directly as point loads, same steps")
    # at rest? the coupled load over the averaging window (an alternating load averaged over an odd number of
    # steps would bias the reference load) and the settlement change of both runs over the last output interval
    fy_win = -it["fy_mpm"].to_numpy()[-every:] / th
    ser = pd.read_csv(ctx.out_dir / tag / "interface_series.csv")
    times = np.sort(ser["t"].unique())
    uy_prev = ser.loc[ser["t"] == times[-2]].sort_values("point")["uy"].to_numpy()
    rest = {"load_spread": float(np.ptp(fy_win) / abs(fy_win.mean())),
            "drift_coupled": abs(s_c + float(uy_prev[under].mean())) / s_c,
            "drift_direct": abs(s_d + float(u_dir_back[under, 1].mean())) / s_d, "window_steps": every}
    ctx.notes.append(f"at rest: interface load over the averaging window ({every} steps) {fy_win.min():.5g} to "
                     f"{fy_win.max():.5g} N/m (spread {100 * rest['load_spread']:.3g} % of the mean); settlement "
                     f"change over the last output interval: coupled {100 * rest['drift_coupled']:.3g} %, "
                     f"direct {100 * rest['drift_direct']:.3g} %")

    log = read_log(ctx, tag)
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.2))
    plot_interface(a1, a2, res, log)
    a1.axhline(-M * g, color="k", ls=":", lw=0.8, label="-M g")
    a1.set_ylim(-3 * M * g, M * g)
    a3.plot(pts["x0"], -pts["uy"] * 1e6, "o-", ms=3, label="coupled")
    a3.plot(pts["x0"], -u_dir[:, 1] * 1e6, "x--", ms=4, label="direct point loads")
    a3.set_xlabel("x [m]"); a3.set_ylabel("settlement of the top [um]"); a3.legend()
    fig.tight_layout()
    ctx.save_plot(fig)
    ctx.notes.append(f"interface work: DEM side {bal['work_dem']:.4g} J, MPM side {bal['work_mpm']:.4g} J")
    return rest
