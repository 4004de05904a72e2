"""The native implicit scheme against Kratos' implicit MPM on KRATOS' discretization (issue 18): a cross-code
check of the implicit solver, and the same-work wall time of the whole collapse.

The case's own scene (quadratic B-splines, Coulomb friction base, geostatic start, cfl 5) is not what the stored
Kratos runs solve (bilinear shapes, the no-slip substitute of the base, a stress-free start, Kratos' dt = the
explicit cfl-0.5 step: adapters/kratos/params.py). Here the native implicit solver is run on that discretization
(params.native_same_discretization: the overrides, the transfer FLIP like Kratos' Newmark update) over the whole
1 s collapse, at h = 10 mm (default) and 5 mm (--full), and scored with the same bui_metrics as the stored Kratos
run of that h (reference_runs/mpm_bui_collapse/kratos). What still differs by construction: the seeding (Kratos'
Gauss points, the native cell sub-centres), the law (Kratos' finite-strain Hencky Mohr-Coulomb) and the linear
solver. Tolerance of each row: Kratos' own change of that metric between its stored h = 10 and 5 mm runs (its
discretization error at h = 10 mm, estimated): two codes that solve the same discrete problem should differ by
less than one of them moves under refinement.

Modified Newton (`[mpm.implicit] reuse_ratio`, the LU factor kept within and across steps): the h = 10 mm run again
with reuse_ratio = MODIFIED_NEWTON_REUSE; the same residual tolerance, so it must give the full-Newton collapse:
its surface may differ from the full-Newton run's by at most MODIFIED_NEWTON_SHARE of the yardstick above (a solver
option has to stay an order of magnitude below the discretization error). Its wall time is in the notes."""
from __future__ import annotations

import math

from coupler.scene import Scene, load_scene
from validation.cases.mpm_bui_collapse.kratos_bench import MODIFIED_NEWTON_REUSE   # the bench's variant, too
from validation.cases.mpm_bui_collapse.metrics import bui_metrics
from validation.metrics import rms

SIZES = {"default": (0.01,), "full": (0.01, 0.005)}
YARDSTICK = (0.01, 0.005)       # Kratos' stored runs whose difference is each row's tolerance
MODIFIED_NEWTON_SHARE = 0.1     # its surface vs the full-Newton run: at most this share of the yardstick
# (metric key of bui_metrics, row label, unit)
METRICS = (("runout", "run-out", "m"), ("angle", "failure-line angle", "deg"), ("area", "deposit area", "m^2"),
           ("volume_change", "volume change", "-"))


def kratos_stored(h: float):
    """(Kratos scene at h, stored result, provenance) or (scene, None, why)."""
    from validation.cases.mpm_bui_collapse import kratos_runs as KR
    sc = KR.kratos_scene(h)
    res, why, prov = KR.stored(h, sc)
    return sc, res, (prov if res is not None else why)


def native_scene(implicit: Scene, h: float, ksc: Scene, kratos_dt: float, reuse_ratio: float = 0.0) -> Scene:
    """The implicit case scene on Kratos' discretization at cell size h (Kratos' dt of its stored run); reuse_ratio
    > 0: with the modified-Newton option."""
    from adapters.kratos.params import native_same_discretization
    from validation.cases.mpm_bui_collapse import kratos_runs as KR
    ov = native_same_discretization(ksc, kratos_dt, stress_free_start=True, friction=KR.FRICTION)
    if reuse_ratio > 0.0:
        ov["mpm.implicit.reuse_ratio"] = reuse_ratio
    return load_scene(implicit.source, overrides={"mpm.grid.cell_size": h, **ov},
                      name="mpm_bui_implicit_kratos_discretization" + ("_modified_newton" if reuse_ratio else ""))


def rows(ctx, implicit: Scene) -> None:
    kr = {h: kratos_stored(h) for h in YARDSTICK}
    missing = [f"h={h * 1000:g} mm: {v[2]}" for h, v in kr.items() if v[1] is None]
    if missing:
        ctx.fail("same discretization as Kratos: stored Kratos runs", "; ".join(missing), backend="kratos")
        return
    km = {h: bui_metrics(res.particles[-1][1], sc) for h, (sc, res, _) in kr.items()}
    ha, hb = YARDSTICK
    tol = {key: abs(km[ha][key] - km[hb][key]) for key, *_ in METRICS}
    tol["surface"] = rms(km[ha]["surf_at_exp"] - km[hb]["surf_at_exp"])
    yard = f"Kratos' own change h={ha * 1000:g} -> {hb * 1000:g} mm (stored runs)"
    for h in SIZES["full" if ctx.full else "default"]:
        ksc, kres, prov = kr[h]
        scene = native_scene(implicit, h, ksc, kres.summary["dt"])
        tag = f"kratos_discretization_h{h * 1000:g}mm"
        res = ctx.run(scene, tag=tag)
        wall = ctx.wall_times[tag]
        m, mk, s, ks = bui_metrics(res.particles[-1][1], scene), km[h], res.summary, kres.summary
        lab = f"same discretization as Kratos h={h * 1000:g} mm"
        kw = float(prov["wall_time_s"])
        ctx.notes.append(
            f"{lab}: native implicit (linear shapes, no-slip base, stress-free start, FLIP, dt {s['dt']:.4g} s, "
            f"{s['steps']} steps) {wall:.1f} s, Newton {s['newton_iterations_mean']:.2f} / "
            f"{s['newton_iterations_max']} (mean / max), {s['step_cuts']} cuts, "
            f"{s['particles'] * s['steps'] / wall:.3g} MP-steps/s; Kratos stored run ({prov.get('date', '')}) "
            f"{kw:.0f} s, Newton {ks.get('newton_iterations_mean', math.nan):.2f}, "
            f"{prov.get('mp_steps_per_s', math.nan):.3g} MP-steps/s: whole collapse {kw / wall:.1f}x faster "
            f"(Kratos' time from its provenance, another minute of this or another machine; the bench compares "
            f"the two in one run); native run-out {m['runout']:.3f} / Kratos {mk['runout']:.3f} m, failure line "
            f"{m['angle']:.2f} / {mk['angle']:.2f} deg, volume change {m['volume_change']:+.4f} / "
            f"{mk['volume_change']:+.4f} (both codes gain volume with linear shapes); native points ahead of "
            f"Kratos' run-out by more than h: {int((res.particles[-1][1]['x'] > mk['runout'] + h).sum())} of "
            f"{m['n_points']} (isolated points sliding ahead of the front)")
        ctx.check_max(f"{lab}: points lost [-]", m["lost"], 0, wall_time_s=wall,
                      note=f"{m['n_points']} of {m['n_expected']} seeded")
        ctx.check_max(f"{lab}: surface RMS difference native vs Kratos [m]",
                      rms(m["surf_at_exp"] - mk["surf_at_exp"]), tol["surface"], wall_time_s=wall,
                      note=f"at the experiment's x; tolerance: {yard} {tol['surface'] * 1e3:.2f} mm; RMS vs the "
                           f"experiment native {m['rms'] * 1e3:.2f} / Kratos {mk['rms'] * 1e3:.2f} mm")
        for key, name, unit in METRICS:
            ctx.check_abs(f"{lab}: {name} native vs Kratos [{unit}]", m[key], mk[key], tol[key], wall_time_s=wall,
                          note=f"tolerance: {yard}, {tol[key]:.4g} {unit}")
        if h == SIZES["default"][0]:
            modified_newton(ctx, native_scene(implicit, h, ksc, kres.summary["dt"], MODIFIED_NEWTON_REUSE), h, m, wall,
                            tol["surface"], yard)


def modified_newton(ctx, sc: Scene, h: float, m_full: dict, wall_full: float, yard_tol: float, yard: str) -> None:
    """The same run with the modified-Newton option: the surface against the full-Newton run's, and the wall time."""
    tag = f"kratos_discretization_h{h * 1000:g}mm_modified_newton"
    res = ctx.run(sc, tag=tag)
    wall, s = ctx.wall_times[tag], res.summary
    m = bui_metrics(res.particles[-1][1], sc)
    lab = f"same discretization as Kratos h={h * 1000:g} mm, modified Newton (reuse_ratio {MODIFIED_NEWTON_REUSE:g})"
    ctx.notes.append(f"{lab}: {wall:.1f} s vs full Newton {wall_full:.1f} s ({wall_full / wall:.2f}x), Newton "
                     f"{s['newton_iterations_mean']:.2f} / {s['newton_iterations_max']} (mean / max), "
                     f"{s['step_cuts']} cuts; run-out {m['runout']:.4f} / {m_full['runout']:.4f} m, volume change "
                     f"{m['volume_change']:+.4f} / {m_full['volume_change']:+.4f} (modified / full)")
    ctx.check_max(f"{lab}: surface RMS difference vs full Newton [m]", rms(m["surf_at_exp"] - m_full["surf_at_exp"]),
                  MODIFIED_NEWTON_SHARE * yard_tol, wall_time_s=wall,
                  note=f"tolerance: {MODIFIED_NEWTON_SHARE:g} x ({yard} {yard_tol * 1e3:.2f} mm): a solver option "
                       f"an order of magnitude below the discretization error")
