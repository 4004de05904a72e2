"""The dense-pack settling check of the hard cases (hard_dem: reduced pack; hard_dem_settling_full: 50,000 spheres).

Metrics (energy.csv, every output time):
  * energy gain: max over t of (K + P + E_el + D)(t) - (K + P + E_el + D)(0), relative to the potential energy
    released, <= 1 % (D accumulated from the contact work, not a residual; the same bound as dem_collapse_energy);
  * kinetic energy non-increasing after the initial impacts: from t* (the first output after the kinetic-energy
    peak with K < 10 % of the peak) on, the largest rise of K above its running minimum, relative to the peak,
    <= 1 % (a late local rearrangement may release some potential energy, so not 0; an unstable step pumps K up
    by far more).
"""
from __future__ import annotations

import numpy as np

from validation.metrics import total_energy


def settling_checks(ctx, scene, tag: str, label: str) -> dict:
    res = ctx.run(scene, tag=tag)
    wall = ctx.wall_times[tag]
    e = res.energy
    released = float(e["potential"].iloc[0] - e["potential"].min())
    total = total_energy(e)
    ctx.check_max(f"{label}: energy gain / released potential energy", float(max(0.0, (total - total[0]).max()))
                  / released, 0.01, wall_time_s=wall)
    k = e["kinetic"].to_numpy()
    t = e["t"].to_numpy()
    ipk = int(np.argmax(k))
    after = np.nonzero((np.arange(len(k)) > ipk) & (k < 0.1 * k[ipk]))[0]
    if len(after) == 0:
        ctx.fail(f"{label}: kinetic energy rise after the impacts / peak", "kinetic energy never fell below 10 % "
                 "of its peak: the pack did not settle")
        rise, t_star = float("nan"), float("nan")
    else:
        i0 = int(after[0])
        ks = k[i0:]
        rise = float((ks - np.minimum.accumulate(ks)).max() / k[ipk])
        t_star = float(t[i0])
        ctx.check_max(f"{label}: kinetic energy rise after the impacts / peak", rise, 0.01, wall_time_s=wall,
                      note=f"from t* = {t_star:.3g} s (K < 10 % of its peak at {t[ipk]:.3g} s)")
    sm = res.summary
    ctx.notes.append(f"{label}: {sm['particles']} spheres, {sm['steps']} steps of dt {sm['dt']:.3g} s (auto: "
                     f"{sm['dt_limit_reason']}), {wall:.1f} s wall, {sm['particles'] * sm['steps'] / wall:.3g} "
                     f"particle-steps/s; K at the end {k[-1]:.3g} J (peak {k[ipk]:.3g} J)")
    return {"t": t, "kinetic": k, "total": total, "released": released, "t_star": t_star, "wall": wall}
