"""Bui et al. (2008) collapse metrics: ONE code for every backend (native explicit, native implicit, Kratos).

    bui_metrics(particles_frame, scene) -> dict

particles_frame: the final material-point table of any backend (columns x, y, ux, uy, volume; eps_p optional:
NaN for Kratos), scene: the scene that was run (cell size h, points per cell, body outline). Definitions:

  surface s(x): per x-bin of one cell width h, the highest material-point centre ("raw"), or that + half the
    initial point size 0.5 h / ppc ("half point": the top of the point's own area, the default everywhere);
    empty bin = 0 (validation.metrics.surface_profile)
  rms, rms_raw: RMS vertical error of s at the experimental points with x in [0, 0.46] m
  runout: first bin centre with s < RUNOUT_H (2 mm, 1 % of the column height above the base)
  wall: s of the first bin (height at the wall); toe: s at the experimental toe point = the first experimental
    point with y <= 10 % of the initial column height (0.380 m, 0.008 m)
  area: integral of s (half point) [m^2 per unit depth]
  angle (+ fit = (angle, a, b)): the static wedge's failure line as the fitted angle. Static = final |u| < 2 mm.
    Per initial row of points (same y0) the edge is the midpoint between the last point of the static run from
    the wall and the first mobile point; rows static over their whole length (the layer held by the base) have
    no edge; least-squares y0 = a + b x0 through the edges, angle = atan(-b) (the experiment's fit, y on x)
  fl_offset_mean, fl_offset_rms (+ fl_x_model, fl_used): the failure line point-wise. At each experimental
    failure-line height y_e, the smallest initial x of the points of the row nearest to y_e that moved more than
    2 mm (the first mobile point from the wall), minus the experimental x_e; mean and RMS over the heights where
    that row has a mobile point (fl_used counts them; the others are NaN in fl_x_model)
  volume_change: sum of point volumes / initial body area - 1 (solver check: <= 1 %, the material is plastically
    incompressible, psi = 0, and its elastic compression under 0.1 m of itself is ~0.3 %)
  n_points, n_expected, lost: points in the frame, points the body was seeded with (ppc^2 per covered cell),
    the difference (solver check: no point lost)
"""
from __future__ import annotations

import math

import numpy as np

from validation.metrics import read_data, rms, scene_mpm_body_extent, surface_profile

RUNOUT_H = 0.002                       # run-out: where the surface falls below this height [m]
STATIC_U = 0.002                       # displacement threshold of the static wedge [m]
U_SENS = (0.0005, 0.001, 0.002, 0.005, 0.01)      # failure-line threshold sensitivity (|u|) [m]
EPS_SENS = (0.01, 0.05, 0.1, 0.2)                 # and with accumulated plastic strain instead
X_MAX_EXP = 0.46                       # surface error over the experimental points up to here [m]
TOE_FRACTION = 0.10                    # toe point: first experimental point with y <= this x initial height


def experiment():
    """(final surface, failure line) of the digitized experiment (validation/data)."""
    return read_data("bui2008_final_surface.csv"), read_data("bui2008_failure_line.csv")


def surface(x, y, h, lift, xmax):
    """s(x) per cell-wide bin of the highest point centre + lift (0 raw, 0.5 h / ppc half point)."""
    return surface_profile(np.asarray(x), np.asarray(y) + lift, h, int(round(xmax / h)))


def wedge_edge(x0, y0, mobile):
    """Per initial row: x of the static/mobile transition of the static run starting at the wall (docstring)."""
    xs, ys = [], []
    for y in np.unique(np.round(y0, 9)):
        m = np.isclose(y0, y, rtol=0, atol=1e-9)
        o = np.argsort(x0[m])
        xr, mob = x0[m][o], mobile[m][o]
        if not mob.any():
            continue                     # whole row static: the layer on the base, not the wedge boundary
        k = int(np.argmax(mob))
        xs.append(0.0 if k == 0 else 0.5 * (xr[k - 1] + xr[k]))
        ys.append(y)
    return np.array(xs), np.array(ys)


def line_angle(xs, ys):
    """Least-squares y = a + b x; returns (angle [deg], a, b)."""
    if len(xs) < 3 or np.ptp(xs) == 0.0:
        return float("nan"), float("nan"), float("nan")
    b, a = np.polyfit(xs, ys, 1)
    return float(math.degrees(math.atan(-b))), float(a), float(b)


def failure_line_offsets(x0, y0, u, fl_exp, threshold=STATIC_U):
    """Point-wise failure line (docstring): per experimental height, the smallest x0 of the mobile points
    (|u| > threshold) of the nearest initial row, minus the experimental x. Returns (x_model, offsets)."""
    rows = np.unique(np.round(y0, 9))
    xm = np.full(len(fl_exp), np.nan)
    for k, (xe, ye) in enumerate(fl_exp):
        r = rows[int(np.argmin(np.abs(rows - ye)))]
        sel = np.isclose(y0, r, rtol=0, atol=1e-9) & (u > threshold)
        if sel.any():
            xm[k] = float(x0[sel].min())
    return xm, xm - fl_exp[:, 0]


def n_seeded(scene, k: int = 0) -> int:
    """Points the k-th body was seeded with: ppc^2 per cell of the (rectangular) outline."""
    lo, hi = scene_mpm_body_extent(scene, k)
    h = scene.mpm.cell_size
    ppc = scene.mpm.bodies[k].particles_per_cell
    return int(round((hi[0] - lo[0]) / h)) * int(round((hi[1] - lo[1]) / h)) * ppc * ppc


def bui_metrics(particles_frame, scene) -> dict:
    """All Bui metrics of one final material-point table (module docstring). Scalars plus the arrays the case
    plots (xc, top, surf_at_exp, x_exp, err_at_exp, x0, y0, u, edges, fl_x_model)."""
    df = particles_frame
    exp, fl_exp = experiment()
    h = scene.mpm.cell_size
    ppc = scene.mpm.bodies[0].particles_per_cell
    xmax = float(scene.mpm.size[0])
    lo, hi = scene_mpm_body_extent(scene)
    x, y = df["x"].to_numpy(float), df["y"].to_numpy(float)
    xc, top = surface(x, y, h, 0.5 * h / ppc, xmax)
    _, top_raw = surface(x, y, h, 0.0, xmax)
    sel = exp[:, 0] <= X_MAX_EXP + 1e-9
    ys = np.interp(exp[sel, 0], xc, top)
    ys_raw = np.interp(exp[sel, 0], xc, top_raw)
    low = np.nonzero(top < RUNOUT_H)[0]
    toe_k = int(np.nonzero(exp[:, 1] <= TOE_FRACTION * (hi[1] - lo[1]))[0][0])
    x0 = (df["x"] - df["ux"]).to_numpy(float)
    y0 = (df["y"] - df["uy"]).to_numpy(float)
    u = np.hypot(df["ux"], df["uy"]).to_numpy(float)
    edges = wedge_edge(x0, y0, u >= STATIC_U)
    fit = line_angle(*edges)
    xm, off = failure_line_offsets(x0, y0, u, fl_exp)
    ok = np.isfinite(off)
    area0 = float((hi[0] - lo[0]) * (hi[1] - lo[1]))
    vol = float(df["volume"].sum()) if "volume" in df else float("nan")
    n_exp = n_seeded(scene)
    return dict(rms=rms(ys - exp[sel, 1]), rms_raw=rms(ys_raw - exp[sel, 1]),
                runout=float(xc[low[0]]) if len(low) else float("nan"), wall=float(top[0]),
                toe=float(np.interp(exp[toe_k, 0], xc, top)), toe_x=float(exp[toe_k, 0]),
                toe_exp=float(exp[toe_k, 1]), area=float(np.sum(top) * h),
                angle=fit[0], fit=fit, edges=edges,
                fl_offset_mean=float(np.mean(off[ok])) if ok.any() else float("nan"),
                fl_offset_rms=rms(off[ok]) if ok.any() else float("nan"), fl_used=int(ok.sum()),
                fl_x_model=xm, fl_offsets=off,
                volume_change=vol / area0 - 1.0, n_points=int(len(df)), n_expected=n_exp, lost=n_exp - int(len(df)),
                xc=xc, top=top, top_raw=top_raw, surf_at_exp=ys, x_exp=exp[sel, 0], err_at_exp=ys - exp[sel, 1],
                x0=x0, y0=y0, u=u)


def experiment_line_under_model_sampling(row_heights) -> float:
    """The fitted angle of the EXPERIMENTAL failure line when it is sampled like the model's wedge edges: the
    experimental x(y) (piecewise linear through the digitized points) read at the model's row heights inside the
    experimental height range, then the same y-on-x least-squares fit. Separates what the fit's sampling does to
    the angle from what the model does."""
    _, fl = experiment()
    o = np.argsort(fl[:, 1])
    yy = np.asarray([y for y in row_heights if fl[:, 1].min() <= y <= fl[:, 1].max()])
    xx = np.interp(yy, fl[o, 1], fl[o, 0])
    return line_angle(xx, yy)[0]
