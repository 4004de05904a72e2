"""DEM granular column collapse between codes: 2,000 polydisperse spheres (R 1.5-2.5 mm, seeded packing of a
0.1 m x 0.6 m column), planar, soft grains (E = 70 MPa, nu = 0.33, rho = 2700; e = 0.5, mu = 0.5, no rolling
resistance), floor and back wall, 0.4 s; the same scene file in native, LIGGGHTS and YADE.
Profile h(x) = highest sphere top in 1 cm bins. Metrics vs each code: RMS of h_native - h_code over the bins
occupied in either, relative to the initial column height (<= 5 %), median x and run-out (90th percentile of x)
within 5 %. A granular collapse is chaotic grain by grain, so only the macroscopic profile is compared."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.metrics import rms, surface_profile

TITLE = "DEM column collapse: final profile, native vs LIGGGHTS vs YADE"
FULL_ONLY = False
REFERENCE_CODES = ("liggghts", "yade")
TOL = 0.05
BIN = 0.01


def reference_scenes(case_dir):
    from coupler.scene import load_scene
    return {"column": load_scene(case_dir / "column.toml")}


def _final(res, radius):
    b = res.bodies
    last = b[np.isclose(b["t"], b["t"].max())]
    return last["x"].to_numpy(), last["y"].to_numpy() + radius[last["body"].map(lambda n: int(n.split(":")[1])).to_numpy()]


def profile(x, top, xmax):
    """h(x): the highest sphere top per 1 cm bin over [0, xmax) (metrics.surface_profile)."""
    return surface_profile(x, top, BIN, int(round(xmax / BIN)))


def evaluate(ctx):
    scene = ctx.scene("column.toml")
    radius = scene.dem.radius
    h0 = float((scene.dem.position[:, 1] + radius).max())
    nat = ctx.run(scene)
    wn = ctx.wall_times[f"{scene.name}_native"]
    xn, tn = _final(nat, radius)
    xmax = 0.6
    xc, hn = profile(xn, tn, xmax)
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(xc, hn, "k-", lw=2, label=f"native ({wn:.1f} s)")
    for code in REFERENCE_CODES:
        ref = ctx.reference(code, "column", scene)
        if ref is None:
            ctx.fail(f"profile vs {code}", ctx.notes[-1], backend=code)
            continue
        wr = float(ref.summary["wall_time_s"])
        xr, tr = _final(ref, radius)
        _, hr = profile(xr, tr, xmax)
        occ = (hn > 0) | (hr > 0)
        d_rms = rms(hn[occ] - hr[occ])
        ctx.check_max(f"profile RMS difference / initial height vs {code}", d_rms / h0, TOL, backend=code,
                      wall_time_s=wr, note=f"RMS {d_rms * 1e3:.2f} mm, initial height {h0 * 1e3:.0f} mm")
        ctx.check_rel(f"median x vs {code}", float(np.median(xn)), float(np.median(xr)), TOL, backend=code,
                      wall_time_s=wr)
        ctx.check_rel(f"run-out (90th percentile x) vs {code}", float(np.percentile(xn, 90)),
                      float(np.percentile(xr, 90)), TOL, backend=code, wall_time_s=wr)
        ax.plot(xc, hr, "--", label=f"{code} ({wr:.1f} s)")
    ax.set(xlabel="x [m]", ylabel="surface height [m]", title="final profile at t = 0.4 s (1 cm bins)")
    ax.legend()
    ctx.save_plot(fig)
