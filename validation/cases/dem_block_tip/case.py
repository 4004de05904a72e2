"""Block tip (issue #4): standing 5 x 6 block (exact mass and inertia, I_zz about the COM) on an incline emulated
by tilted gravity, mu = 0.9. Reference: the rigid block rotating on its downhill bottom sphere, which rolls without
slip on the floor (a rigid pivot that moves by R theta), integrated with scipy under the same g(t) (not linearised).

(a) Tilting table (tilt.toml): the block stands at 30 deg while its contacts settle, the incline tilts to 35 deg
    at 1 deg / 4 ms. The rigid block starts to pivot when gravity passes atan(2/3) = 33.69 deg. Compared at the times
    the rigid rotation reaches 0.5, 2, 5 and 10 deg (the early tip), within 2 %.
(b) Step load (block.toml, gravity at 35 deg from t = 0 on a block with unloaded contacts): the rigid pivot started
    from the DEM state at T0 = 5 ms, once the block stands on its pivot sphere alone, within 2 % at 0.05, 0.10, 0.12 s.
    Against the rigid pivot from rest the step-loaded DEM block leads by ~15 % at 0.05 s: the tangential springs
    start at zero and overshoot, which kicks the block into its unstable mode; this is the loading, not the rigid
    body dynamics (the tilting table removes it), and it is reported as a measurement, not a check.
"""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.integrate import solve_ivp

from validation.metrics import rotation_z_deg, scene_cluster, sphere_mass

TITLE = "Rigid cluster: block tipping on an incline vs rigid pivot"
FULL_ONLY = False
TIMES = (0.05, 0.10, 0.12)
T0 = 0.005
MILESTONES_DEG = (0.5, 2.0, 5.0, 10.0)


def pivot_solution(scene, t_eval, y0=(0.0, 0.0)):
    """Rigid block tipping on its downhill (+x) bottom sphere, which rolls without slip on the floor (the contact point
    moves by R theta). Lagrange: (M |J|^2 + I_c) th'' + M (J . J') th'^2 = M g . J, with J = dC/dth the
    derivative of the COM position C(th). Block geometry (equal members of the template of cluster "block") and
    density from the scene. Returns the rotation in degrees (positive = downhill)."""
    _, tpl, mat = scene_cluster(scene, "block")
    assert (tpl.radii == tpl.radii[0]).all(), "equal members"
    r = float(tpl.radii[0])
    m = sphere_mass(mat.density, r)
    centre = 0.5 * (tpl.offsets.min(axis=0) + tpl.offsets.max(axis=0))   # COM of the full grid of equal members
    xs, ys = tpl.offsets[:, 0] - centre[0], tpl.offsets[:, 1] - centre[1]
    M = len(tpl.radii) * m
    Ic = float(np.sum(0.4 * m * r * r + m * (xs ** 2 + ys ** 2)))
    bottom = np.isclose(ys, ys.min())
    pivot = np.argmax(np.where(bottom, xs, -np.inf))   # the downhill bottom sphere
    dx, dy = -xs[pivot], -ys[pivot]                # COM relative to the centre of the downhill bottom sphere

    def rhs(t, y):
        th, om = y                                  # rotation about z (negative = downhill)
        g = scene.gravity_at(t)[:2]
        c, s = math.cos(th), math.sin(th)
        J = np.array([-r - s * dx - c * dy, c * dx - s * dy])
        Jp = np.array([-c * dx + s * dy, -s * dx - c * dy])
        acc = (M * (g @ J) - M * (J @ Jp) * om * om) / (M * (J @ J) + Ic)
        if th == 0.0 and om == 0.0 and acc > 0.0:   # still standing: the floor holds the uphill edge
            acc = 0.0
        return [om, acc]

    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), list(y0), t_eval=t_eval, rtol=1e-10, atol=1e-13, max_step=1e-3)
    return np.degrees(-sol.y[0])


def _angle(res):
    b = res.body("block")
    return b["t"].to_numpy(), -rotation_z_deg(b)          # positive = downhill


def evaluate(ctx):
    # (a) tilting table, from rest
    tilt = ctx.scene("tilt.toml")
    t_a, ang_a = _angle(ctx.run(tilt))
    wall_a = ctx.wall_times[f"{tilt.name}_native"]
    tf = np.linspace(0.0, t_a[-1], 20001)
    ref_f = pivot_solution(tilt, tf)
    ref_a = np.interp(t_a, tf, ref_f)
    for a in MILESTONES_DEG:
        ts = float(np.interp(a, ref_f, tf))          # ref_f increases monotonically once the tip starts
        ctx.check_rel(f"tilting table: rotation when the rigid pivot reaches {a:g} deg (t = {ts:.4f} s) [deg]",
                      float(np.interp(ts, t_a, ang_a)), a, 0.02, wall_time_s=wall_a)
    # (b) step load at 35 deg
    scene = ctx.scene("block.toml")
    t, angle = _angle(ctx.run(scene))
    wall = ctx.wall_times[f"{scene.name}_native"]
    ref = pivot_solution(scene, t)
    k0 = int(np.argmin(abs(t - T0)))
    rate = np.gradient(np.radians(angle), t)
    ref0 = np.full_like(t, np.nan)
    ref0[k0:] = pivot_solution(scene, t[k0:], (-math.radians(angle[k0]), -rate[k0]))
    lead = []
    for ts in TIMES:
        k = int(np.argmin(abs(t - ts)))
        ctx.check_rel(f"step load: angle at t = {ts:g} s, pivot started from the DEM state at {T0:g} s [deg]",
                      float(angle[k]), float(ref0[k]), 0.02, wall_time_s=wall)
        lead.append(f"{100 * (angle[k] / ref[k] - 1):+.1f} % at {ts:g} s")
    ctx.notes.append("step load, DEM vs rigid pivot from rest (measurement, not a check: the zero-history tangential "
                     "springs overshoot and kick the block; the tilting table removes it): " + ", ".join(lead))
    fig, axs = plt.subplots(1, 2, figsize=(12, 4))
    axs[0].plot(t_a, ang_a, label="native, tilting table 30 -> 35 deg")
    axs[0].plot(t_a, ref_a, "k:", label="rigid pivot, same g(t)")
    axs[0].set(xlabel="t [s]", ylabel="rotation [deg]", title="(a) tilting table")
    axs[1].plot(t, angle, label="native, step load at 35 deg")
    axs[1].plot(t, ref, "k:", label="rigid pivot from rest")
    axs[1].plot(t, ref0, "r--", label=f"rigid pivot from the DEM state at {T0:g} s")
    axs[1].set(xlabel="t [s]", ylabel="rotation [deg]", title="(b) step load")
    for ax in axs:
        ax.legend()
    ctx.save_plot(fig)
