"""Bui et al. (2008) granular column collapse, MPM (bspline2, APIC, Mohr-Coulomb) vs the digitized experiment.

Free surface of the deposit: per x-bin of one cell width, the highest material point + half the point spacing
(empty bin = 0). Metrics at the scene resolution (h = 2.5 mm):
  RMS vertical error over x in [0, 0.46] vs bui2008_final_surface.csv (<= 4 mm)
  run-out = first bin centre with surface height < 2 mm (10 % of 0.44 m)
  height at the wall (first bin) 0.100 +- 0.002 m
  failure-line angle: boundary of the static wedge (points displaced < 2 mm) per initial layer, least-squares line
    x0(y0), angle = atan(-dy/dx) (33 +- 3 deg)
  deposit area = integral of the surface height (5 % of 0.020 m^2)
Sweep: h = 10, 5, 2.5 mm (1.25 mm with --full): RMS error vs wall time."""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.scene import load_scene

TITLE = "MPM Bui et al. (2008) column collapse vs experiment + resolution sweep"
FULL_ONLY = False
DATA = Path(__file__).resolve().parents[2] / "data"


def _read(path):
    rows = [l for l in path.read_text().splitlines() if l and not l.startswith("#")]
    return np.array([[float(v) for v in r.split(",")] for r in rows[1:]])


def surface(df, h, ppc, xmax=0.55):
    x, y = df["x"].to_numpy(), df["y"].to_numpy()
    nb = int(round(xmax / h))
    top = np.zeros(nb)
    idx = np.clip((x / h).astype(int), 0, nb - 1)
    np.maximum.at(top, idx, y + 0.5 * h / ppc)
    xc = (np.arange(nb) + 0.5) * h
    return xc, top


def metrics(res, scene, exp):
    h = scene.mpm.cell_size
    ppc = scene.mpm.bodies[0].particles_per_cell
    _, df = res.particles[-1]
    xc, top = surface(df, h, ppc)
    sel = exp[:, 0] <= 0.46 + 1e-9
    ys = np.interp(exp[sel, 0], xc, top)
    rms = float(np.sqrt(np.mean((ys - exp[sel, 1]) ** 2)))
    low = np.nonzero(top < 0.002)[0]
    runout = float(xc[low[0]]) if len(low) else float("nan")
    wall_h = float(top[0])
    area = float(np.sum(top) * h)
    # failure line: static wedge = points with displacement < 2 mm; per initial layer its largest x0
    x0 = (df["x"] - df["ux"]).to_numpy()
    y0 = (df["y"] - df["uy"]).to_numpy()
    static = np.hypot(df["ux"], df["uy"]).to_numpy() < 0.002
    xs, yl = [], []
    for y in np.unique(np.round(y0, 9)):
        m = np.isclose(y0, y) & static
        if m.any() and x0[m].max() < 0.2 - h:
            xs.append(x0[m].max())
            yl.append(y)
    if len(xs) >= 3:
        slope = np.polyfit(xs, yl, 1)[0]
        angle = float(math.degrees(math.atan(-slope)))
    else:
        angle = float("nan")
    return dict(rms=rms, runout=runout, wall=wall_h, area=area, angle=angle, xc=xc, top=top,
                fl=(np.array(xs), np.array(yl)))


def evaluate(ctx):
    exp = _read(DATA / "bui2008_final_surface.csv")
    fl_exp = _read(DATA / "bui2008_failure_line.csv")
    base = ctx.scene("scene.toml")
    sizes = [0.01, 0.005, 0.0025] + ([0.00125] if ctx.full else [])
    sweep = []
    main = None
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(13, 4.5))
    for h in sizes:
        scene = load_scene(base.source, overrides={"mpm.grid.cell_size": h})
        tag = f"h{h * 1000:g}mm"
        res = ctx.run(scene, tag=tag)
        wall = ctx.wall_times[tag]
        m = metrics(res, scene, exp)
        sweep.append((h, m["rms"], wall, res.summary["particles"]))
        ctx.check_max(f"h={h * 1000:g} mm: surface RMS error [m]", m["rms"], 0.004, wall_time_s=wall,
                      note=f"{res.summary['particles']} points, {res.summary['steps']} steps")
        a1.plot(m["xc"], m["top"], "-", label=f"MPM h={h * 1000:g} mm")
        if abs(h - base.mpm.cell_size) < 1e-12:
            main = (m, wall)
    m, wall = main
    ctx.check_rel("run-out (height < 2 mm) [m]", m["runout"], 0.44, 0.10, wall_time_s=wall)
    ctx.check_abs("height at the wall [m]", m["wall"], 0.100, 0.002, wall_time_s=wall)
    ctx.check_abs("failure-line angle [deg]", m["angle"], 33.0, 3.0, wall_time_s=wall,
                  note="static wedge: displacement < 2 mm")
    ctx.check_rel("deposit area [m^2]", m["area"], 0.020, 0.05, wall_time_s=wall)
    a1.plot(exp[:, 0], exp[:, 1], "ko", ms=4, label="experiment (Bui 2008)")
    a1.plot(fl_exp[:, 0], fl_exp[:, 1], "ks--", ms=3, mfc="none", label="exp. failure line")
    a1.plot(*m["fl"], "r.", ms=3, label="MPM static-wedge edge")
    a1.set_xlabel("x [m]"); a1.set_ylabel("y [m]"); a1.set_xlim(0, 0.55); a1.set_aspect("equal"); a1.legend(fontsize=7)
    sw = np.array(sweep)
    a2.loglog(sw[:, 2], sw[:, 1] * 1000, "o-")
    for h, e, w, n in sweep:
        a2.annotate(f"{h * 1000:g} mm", (w, e * 1000))
    a2.axhline(4, color="r", ls=":")
    a2.set_xlabel("wall time [s]"); a2.set_ylabel("surface RMS error [mm]")
    fig.tight_layout()
    ctx.save_plot(fig)
    ctx.notes.append("sweep (h, RMS [m], wall [s], points): " + "; ".join(
        f"{h * 1000:g} mm, {e:.4g}, {w:.1f}, {n}" for h, e, w, n in sweep))
