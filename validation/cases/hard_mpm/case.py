"""Hard cases, MPM (issue #17): extreme stiffness and a fast impact on a fixed grid boundary.

  column.toml  an elastic column under gravity (roller walls, fixed base, local damping to rest), quadratic
               B-splines, run very soft (E = 10 kPa: oedometric strain 7 % at the base, P-wave speed 3.7 m/s) and
               very stiff (E = 1 GPa: 1,160 m/s, a 320x smaller step from the same cfl). Per column:
                 * layer-mean sigma_yy error for layers at least one cell above the base, relative to rho g H
                   (1 %, as mpm_self_weight): sigma_yy(y0) = -rho g (H - y0) holds in the reference coordinate y0
                   at any strain (the weight above y0 does not change);
                 * top settlement against the rate-form (Jaumann hypoelastic, sigma = M ln lambda) solution
                   H - M / (rho g) (1 - exp(-rho g H / M)) (validation/analytic.py; 1 %). The small-strain
                   rho g H^2 / (2 M) is 2.4 % larger for the soft column and equal for the stiff one (note).
  impact.toml  an elastic block (E = 1 MPa) at 10 m/s (Mach 0.27 of its P-wave speed) against the fixed
               (no-slip) bottom of the grid, no gravity, 0.03 s. The run must finish (a blow-up is a failure with
               its message), no material point may leave or be lost (lowest point y >= 0, points kept), the mass is
               kept to round-off (1e-12), and K + E_el may never exceed K0 by more than 1 % (the wall takes energy
               out; it must never put any in).
The cell-crossing study (linear against quadratic B-spline) is hard_mpm_cell_crossing."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.errors import SimulationError
from coupler.scene import load_scene
from validation.analytic import oedometric_modulus, self_weight_settlement, self_weight_settlement_log
from validation.metrics import self_weight_error

TITLE = "Hard cases, MPM: very soft (10 kPa) and very stiff (1 GPa) columns, a 10 m/s impact on a fixed boundary"
FULL_ONLY = False
COLUMNS = {"soft": {"materials.soil.young": 1.0e4, "time.t_end": 3.0, "time.output_interval": 0.5},
           "stiff": {"materials.soil.young": 1.0e9, "time.t_end": 0.03, "time.output_interval": 0.005}}


def column_checks(ctx, scene, label: str, ax) -> None:
    res = ctx.run(scene, tag=label)
    wall = ctx.wall_times[label]
    mat = scene.materials["soil"]
    g = -float(scene.gravity[1])
    h = scene.mpm.cell_size
    _, df = res.particles[-1]
    y0, err, H = self_weight_error(scene, df)
    layers = np.unique(np.round(y0, 9))
    lay = np.array([err[np.isclose(y0, yl)].mean() for yl in layers])
    ctx.check_max(f"{label} (E = {mat.young:g} Pa): layer-mean sigma_yy error, y0 > h [-]",
                  float(np.abs(lay[layers > h]).max()), 0.01, wall_time_s=wall, note="relative to rho g H")
    M = oedometric_modulus(mat.young, mat.poisson)
    u_log = self_weight_settlement_log(mat.density, g, H, M)
    u_lin = self_weight_settlement(mat.density, g, H, M)
    u = float(-df["uy"][y0 > H - h].mean())
    ctx.check_rel(f"{label} (E = {mat.young:g} Pa): top settlement [m]", u, u_log, 0.01, wall_time_s=wall,
                  note=f"rate-form solution; small strain {u_lin:.4g} m ({(u_lin / u_log - 1) * 100:+.2f} %)")
    ctx.notes.append(f"{label} column: {res.summary['steps']} steps of dt {res.summary['dt']:.3g} s, {wall:.1f} s "
                     f"wall; settlement {u:.4g} m = {u / H * 100:.3g} % of H")
    ax.plot(lay * 100, layers, "o-", ms=3, label=f"{label}, E = {mat.young:g} Pa")


def _impact(ctx, ax) -> None:
    scene = ctx.scene("impact.toml")
    try:
        res = ctx.run(scene, tag="impact")
    except SimulationError as e:
        ctx.fail("impact: run finished", f"blow-up: {e}")
        return
    wall = ctx.wall_times["impact"]
    b = res.mpm_bodies
    n0 = int(b["n_points"].iloc[0])
    ctx.check_abs("impact: material points lost", float(n0 - b["n_points"].min()), 0.0, 0.0, wall_time_s=wall)
    ctx.check_max("impact: lowest point below the fixed boundary y = 0, -ymin [m]", float(-b["ymin"].min()), 0.0,
                  wall_time_s=wall)
    m = b["mass"].to_numpy()
    ctx.check_max("impact: mass change / mass", float(np.abs(m - m[0]).max() / m[0]), 1e-12, wall_time_s=wall)
    e = res.energy
    k0 = float(e["kinetic"].iloc[0])
    ke = (e["kinetic"] + e["elastic"]).to_numpy()
    ctx.check_max("impact: max (K + E_el) / K0 - 1", float(ke.max() / k0 - 1.0), 0.01, wall_time_s=wall,
                  note=f"K + E_el at the end: {ke[-1] / k0:.3g} K0")
    ax.plot(e["t"] * 1e3, e["kinetic"] / k0, label="K / K0")
    ax.plot(e["t"] * 1e3, e["elastic"] / k0, label="E_el / K0")
    ax.plot(b["t"] * 1e3, b["ymin"] / scene.mpm.cell_size, label="lowest point y / h")
    ax.set_xlabel("t [ms]")
    ax.set_title(f"10 m/s on a fixed boundary ({res.summary['steps']} steps)", fontsize=9)
    ax.legend(fontsize=8)


def evaluate(ctx):
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for label, ov in COLUMNS.items():
        column_checks(ctx, load_scene(ctx.case_dir / "column.toml", overrides=ov, name=f"hard_column_{label}"),
                      label, a1)
    a1.axvline(1, color="r", ls=":")
    a1.axvline(-1, color="r", ls=":")
    a1.set_xlabel("layer-mean sigma_yy error [% of rho g H]")
    a1.set_ylabel("y0 [m]")
    a1.legend(fontsize=8)
    _impact(ctx, a2)
    fig.tight_layout()
    ctx.save_plot(fig)
