"""Shared pieces of the coupled validation cases (not a case itself: no case.py): the interface force and energy
balance rows and plot every coupled case reports."""
from __future__ import annotations

import numpy as np
import pandas as pd


def read_log(ctx, tag: str) -> pd.DataFrame:
    return pd.read_csv(ctx.out_dir / tag / "coupling_log.csv")


def read_points(ctx, tag: str) -> pd.DataFrame:
    return pd.read_csv(ctx.out_dir / tag / "interface_points.csv")


def interface_balance(ctx, res, tag: str, wall: float, label: str = "") -> dict:
    """Rows: the force the MPM receives equals the force the DEM puts on the wall (round-off); the interface work
    mismatch of the staggered scheme is stated (informative, in the note). Returns the numbers."""
    it = res.interface
    scale = max(float(np.abs(it[["fx_dem", "fy_dem"]].to_numpy()).max()), 1e-300)
    dmax = float(np.abs(it[["fx_mpm", "fy_mpm"]].to_numpy() - it[["fx_dem", "fy_dem"]].to_numpy()).max())
    wd, wm = float(it["work_dem"].iloc[-1]), float(it["work_mpm"].iloc[-1])
    p = f"{label}: " if label else ""
    ctx.check_max(f"{p}interface force MPM vs DEM, max |diff| / max |F| [-]", dmax / scale, 1e-9,
                  wall_time_s=wall, note=f"work on the interface: DEM side {wd:.4g} J, MPM side {wm:.4g} J")
    return {"force_diff": dmax / scale, "work_dem": wd, "work_mpm": wm}


def plot_interface(ax_f, ax_e, res, log: pd.DataFrame, label: str = "") -> None:
    it = res.interface
    ax_f.plot(it["t"], it["fx_dem"], lw=1, label=f"{label} fx DEM on wall")
    ax_f.plot(it["t"], it["fx_mpm"], "--", lw=1, label=f"{label} fx MPM received")
    ax_f.plot(it["t"], it["fy_dem"], lw=1, label=f"{label} fy DEM on wall")
    ax_f.plot(it["t"], it["fy_mpm"], "--", lw=1, label=f"{label} fy MPM received")
    ax_f.set_xlabel("t [s]"); ax_f.set_ylabel("interface force [N]"); ax_f.legend(fontsize=7)
    e = log
    ax_e.plot(e["t"], e["K_dem"] + e["E_dem"], label="DEM K + E_el")
    ax_e.plot(e["t"], e["D_dem"], label="DEM dissipated")
    ax_e.plot(e["t"], e["K_mpm"] + e["E_mpm"], label="MPM K + E_el")
    ax_e.plot(it["t"], it["work_dem"], ":", label="work by DEM on wall")
    ax_e.plot(it["t"], it["work_mpm"], ":", label="work of loads on MPM")
    ax_e.set_xlabel("t [s]"); ax_e.set_ylabel("energy [J]"); ax_e.legend(fontsize=7)
