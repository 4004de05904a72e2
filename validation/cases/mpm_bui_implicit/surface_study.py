"""Does another surface error measure converge faster than the case's? (issue 18, the equal-error comparison)

The case measures every run's final free surface with the Bui cases' definition (validation/cases/mpm_bui_collapse/
metrics.py `surface`: per bin of width h the highest point centre + half a point spacing) and takes its RMS against
the finest run of a stored explicit sequence (reference.STORED; the case's reference: reference.best_candidate) on
reference.REF_X; the case prints this study for each stored Mohr-Coulomb sequence (cfl 0.5, the scene; cfl 0.125)
against its own finest run. That measure is noisy (one point decides a bin, and
the bin width changes with h), so this study compares it with measures that do not depend on the run's h:
  - "5 mm bins": the same max-per-bin surface on fixed 5 mm bins (+ half the run's point spacing);
  - "thickness k": the deposit thickness t(x) = sum_p V_p K_k(x - x_p) (point volume per metre of depth spread
    along x by a tent kernel K_k of half-width k, normalised to unit integral, mirrored at the slip wall x = 0),
    k = 5, 10, 20 mm: an integral (volume) measure, not decided by the top point of a bin.
Per measure: the RMS error of every run against the reference, the self-convergence differences of successive
explicit resolutions (10-5, 5-2.5, 2.5-1.25, 1.25-0.625, 0.625-0.3125 mm) and their observed orders log2(d_i / d_i+1), and the
reference's own error, as the case estimates it (reference.own_error_tail: the differences still to come at the
slowest observed decay) and by Richardson from the two finest runs against it (reference.own_error, e(h) =
C (h^p - h_ref^p), the case's estimate before the twenty-third session). Printed into the case report (case.py) and by
`python -m validation.cases.mpm_bui_implicit.surface_study` (runs the explicit h = 10 and 5 mm itself, ~5 s; the
2.5 mm and finer points are the stored reference runs, reference.load_points). A study, not a check: no rows.
"""
from __future__ import annotations

import math

import numpy as np

from validation.cases.mpm_bui_implicit import reference as REF
from validation.metrics import lattice_triangles, surface_profile

FIXED_BIN = 0.005                       # [m] the fixed-bin surface
KERNELS = (0.005, 0.01, 0.02)           # [m] tent half-widths of the thickness profiles
PPC = 2                                 # points per cell per direction of the Bui scenes (half a point = h / 4)
XMAX_GRID = 0.8                         # [m] grid length (end bin of surface_profile)


def surface_binned(x, y, h, width):
    """Max-per-bin surface on bins of `width` (+ half the run's point spacing h / PPC / 2) on REF_X."""
    xc, top = surface_profile(np.asarray(x), np.asarray(y) + 0.5 * h / PPC, width, int(round(XMAX_GRID / width)))
    return np.interp(REF.REF_X, xc, top)


def thickness(x, vol, k):
    """t(x) on REF_X: sum_p V_p K_k(x - x_p), tent kernel of half-width k (unit integral), mirrored at x = 0."""
    xq = REF.REF_X[:, None]
    t = np.zeros(len(REF.REF_X))
    for xs in (np.asarray(x), -np.asarray(x)):           # the point and its mirror image behind the slip wall
        for i in range(0, len(xs), 8192):                 # chunks: REF_X x points stays small
            r = np.abs(xq - xs[None, i:i + 8192]) / k
            t += (np.clip(1.0 - r, 0.0, None) * vol[None, i:i + 8192]).sum(axis=1) / k
    return t


MEASURES = (("case: max per bin of h", lambda x, y, v, h: surface_binned(x, y, h, h)),
            (f"max per {FIXED_BIN * 1e3:g} mm bin", lambda x, y, v, h: surface_binned(x, y, h, FIXED_BIN))) + tuple(
    (f"thickness, tent {k * 1e3:g} mm", (lambda k: lambda x, y, v, h: thickness(x, v, k))(k)) for k in KERNELS)


def rms(d) -> float:
    return float(math.sqrt(np.mean(np.asarray(d) ** 2)))


def _head(tag: str) -> str:
    """The start of a study line: 'surface study' and the sequence's tag, if any."""
    return f"surface study ({tag})" if tag else "surface study"


def study(explicit: dict, others: dict | None = None, ref_h: float | None = None, tag: str = "",
          seeded: dict | None = None) -> list[str]:
    """Table lines. explicit: {h: (x, y, volume)} of explicit runs including ref_h (the reference; default the
    finest) and at least two coarser ones; others: {label: (x, y, volume, h)} (e.g. the implicit runs), errors only;
    tag: the sequence's name in every line (e.g. "cfl 0.125"); seeded: {h: (x0, y0)} the seeded centres of the
    explicit runs that have them (folding_line)."""
    hs = sorted(explicit, reverse=True)
    ref_h = min(explicit) if ref_h is None else ref_h
    others = others or {}
    lines = [f"{_head(tag)} (surface_study.py): RMS on {len(REF.REF_X)} points x in [0, {REF.X_MAX_REF:g}] m "
             f"[mm]; reference explicit h={ref_h * 1e3:g} mm"]
    for name, f in MEASURES:
        prof = {h: f(*explicit[h], h) for h in hs}
        ref = prof[ref_h]
        err = {h: rms(prof[h] - ref) for h in hs if h != ref_h}
        d = [rms(prof[a] - prof[b]) for a, b in zip(hs, hs[1:])]
        orders = [math.log2(a / b) if a > 0 and b > 0 else float("nan") for a, b in zip(d, d[1:])]
        own = float("nan")
        fine = [h for h in hs if h != ref_h][-2:]          # the two finest runs against the reference
        if len(fine) == 2:
            h2, h1 = fine
            _, own = REF.own_error(h2, h1, ref_h, err[h2], err[h1])
        r_t, own_t = REF.own_error_tail(d)
        e_oth = {lab: rms(f(x, y, v, h) - ref) for lab, (x, y, v, h) in others.items()}
        oth = "; ".join(f"{lab} {e * 1e3:.2f}" for lab, e in e_oth.items())
        # the errors the reference ranks: every run but the finest one of the Richardson pair
        ranked = [e for h, e in err.items() if h != fine[-1]] + list(e_oth.values())
        lines.append(
            f"{_head(tag)}, {name}: explicit " + " / ".join(f"{h * 1e3:g}" for h in err) + " mm: "
            + " / ".join(f"{e * 1e3:.2f}" for e in err.values())
            + "; self-convergence " + " / ".join(f"{a * 1e3:g}-{b * 1e3:g}" for a, b in zip(hs, hs[1:])) + " mm: "
            + " / ".join(f"{x * 1e3:.2f}" for x in d) + " (orders " + ", ".join(f"{o:.2f}" for o in orders) + ")"
            + f"; reference's own error: tail bound (reference.own_error_tail, slowest decay r = {r_t:.2f}) "
            + f"{own_t * 1e3:.2f} = {own_t / min(ranked):.2f}x the smallest error ranked (all runs but the "
            + f"{fine[-1] * 1e3:g} mm one), Richardson ({fine[0] * 1e3:g} / {fine[1] * 1e3:g} mm) {own * 1e3:.2f} = "
            + f"{own / min(ranked):.2f}x"
            + (f"; {oth}" if oth else ""))
    lines.append(area_line(explicit, tag))
    lines.append(base_layer_line(explicit, tag))
    lines.append(folding_line(explicit, seeded or {}, tag))
    lines.append(failure_zone_line(explicit, seeded or {}, tag))
    return lines


def area_and_volume(explicit: dict) -> dict:
    """Does the case's surface enclose the points' volume? {h: (area under the case's surface on REF_X (integral of
    s dx; the deposit ends before X_MAX_REF but for a thin toe), sum of the point volumes)}, per metre of depth. The
    law keeps the volume up to its small elastic change, and the points carry their volume, not their place: a
    shortfall that grows as h shrinks is the point cloud packing denser than the point volumes say (or leaving gaps
    under the top points), which the surface measure sees and a volume measure does not."""
    return {h: (float(np.trapezoid(surface_binned(x, y, h, h), REF.REF_X)), float(np.sum(v)))
            for h, (x, y, v) in explicit.items()}


def area_line(explicit: dict, tag: str = "") -> str:
    """area_and_volume as a line of the study, coarse to fine [cm^2]."""
    av = area_and_volume(explicit)
    return (f"{_head(tag)}, area under the case's surface / sum of point volumes [cm^2] (x in [0, "
            f"{REF.X_MAX_REF:g}] m): "
            + "; ".join(f"{h * 1e3:g} mm {a * 1e4:.2f} / {v * 1e4:.2f} ({a / v - 1.0:+.2%})"
                        for h, (a, v) in sorted(av.items(), reverse=True)))


BASE_LAYER = 0.0025         # [m] the layer above the friction base
BASE_BANDS = ((0.05, 0.25), (0.30, 0.45))   # [m] the deposit's body (thick) and its front (thin, sliding)


def base_layer_density(explicit: dict) -> dict:
    """Where the shortfall of area_and_volume sits: {h: the point volumes per unit area, sum V_p / (layer area), of
    the layer y < BASE_LAYER above the friction base in each x band of BASE_BANDS} (1 where the points sit as densely
    as their volumes say; above 1: packed denser); None for a run whose points start fewer than 2 rows deep in the
    layer (not measured)."""
    out = {}
    for h, (x, y, v) in explicit.items():
        out[h] = None if h / PPC > 0.5 * BASE_LAYER else tuple(
            float(np.sum(v[(x > lo) & (x < hi) & (y < BASE_LAYER)])) / ((hi - lo) * BASE_LAYER)
            for lo, hi in BASE_BANDS)
    return out


def base_layer_line(explicit: dict, tag: str = "") -> str:
    """base_layer_density as a line of the study, coarse to fine ('-': not measured)."""
    dens = base_layer_density(explicit)
    return (f"{_head(tag)}, point volume per unit area in the layer y < {BASE_LAYER * 1e3:g} mm above the base, x in "
            + " / ".join(f"[{lo:g}, {hi:g}]" for lo, hi in BASE_BANDS) + " m: "
            + "; ".join(f"{h * 1e3:g} mm " + ("-" if d is None else " / ".join(f"{x:.3f}" for x in d))
                        for h, d in sorted(dens.items(), reverse=True)))


def folding(explicit: dict, seeded: dict) -> dict:
    """Do the points still sample the deformation? (validation.metrics.lattice_triangles on the seeded lattice, spacing
    h / PPC) {h: (inverted triangles, triangles, and in the base layer under the front (BASE_LAYER, BASE_BANDS[1],
    by the triangles' current centroids): the inverted fraction, the mean area ratio of its triangles (the positions'
    J) and the mean J = V / V0 of their points (F's))} for the runs of explicit with seeded centres in seeded
    ({h: (x0, y0)}). A motion affine at the point spacing has no inverted triangle and the two J equal (thirtieth
    session: under the Bui front neither holds; the triangles turn over gradually, not in a step)."""
    out = {}
    for h, (x0, y0) in seeded.items():
        if h not in explicit:
            continue
        x, y, v = explicit[h]
        ratio, cx, cy, tri = lattice_triangles(x0, y0, x, y, h / PPC)
        jf = v[tri].mean(axis=1) / (h / PPC) ** 2
        lo, hi = BASE_BANDS[1]
        m = (cx > lo) & (cx < hi) & (cy < BASE_LAYER)
        out[h] = (int(np.sum(ratio < 0.0)), len(ratio), float(np.mean(ratio[m] < 0.0)) if m.any() else float("nan"),
                  float(ratio[m].mean()) if m.any() else float("nan"), float(jf[m].mean()) if m.any() else float("nan"))
    return out


def folding_line(explicit: dict, seeded: dict, tag: str = "") -> str:
    """folding as a line of the study, coarse to fine."""
    f = folding(explicit, seeded)
    lo, hi = BASE_BANDS[1]
    return (f"{_head(tag)}, do the points sample the deformation? seeded-lattice triangles "
            f"turned inside out (validation.metrics.lattice_triangles), all / in the layer y < {BASE_LAYER * 1e3:g} mm "
            f"at x in [{lo:g}, {hi:g}] m, and there the positions' J against F's J: "
            + ("; ".join(f"{h * 1e3:g} mm {n} of {nt} / " + (f"{fr:.1%}, J {jp:.3f} against {jf:.3f}" if fr == fr
                                                              else "no triangle in the layer")
                         for h, (n, nt, fr, jp, jf) in sorted(f.items(), reverse=True))
               or "no run with seeded centres"))


ZONE_Y0 = (0.03, 0.04, 0.05, 0.06, 0.07)   # [m] initial heights of the failure-zone rows
ZONE_U = (0.001, 0.01)                    # [m] displacements bounding the zone


def failure_zone(explicit: dict, seeded: dict) -> dict:
    """Where the sliding mass parts from the wedge that stays, in the initial column: per run with seeded centres
    and per initial height y0 in ZONE_Y0 (the row of seeds nearest to it), the initial x0 of the first seed whose
    final displacement exceeds ZONE_U[0] (the failure line) and the distance x0(|u| > ZONE_U[1]) - x0(|u| >
    ZONE_U[0]) (the zone's width: how sharply the displacement rises across it). {h: [(x_line, width), ...]}.
    A law with an internal length would give widths that converge with h; the cohesionless, rate-independent
    Mohr-Coulomb law has none (thirty-third session: the upper rows narrow at every halving)."""
    out = {}
    for h, (x0, y0) in seeded.items():
        if h not in explicit:
            continue
        x, y, _ = explicit[h]
        u = np.hypot(x - x0, y - y0)
        rows = []
        for yv in ZONE_Y0:
            ys = y0[np.argmin(np.abs(y0 - yv))]
            m = np.abs(y0 - ys) < 1e-3 * h
            o = np.argsort(x0[m])
            xs, us = x0[m][o], u[m][o]
            a, b = np.argmax(us > ZONE_U[0]), np.argmax(us > ZONE_U[1])
            rows.append((float(xs[a]), float(xs[b] - xs[a])) if us[b] > ZONE_U[1] else (float("nan"), float("nan")))
        out[h] = rows
    return out


def failure_zone_line(explicit: dict, seeded: dict, tag: str = "") -> str:
    """failure_zone as a line of the study, coarse to fine."""
    f = failure_zone(explicit, seeded)
    return (f"{_head(tag)}, failure zone in the initial column (failure_zone): at y0 = "
            + " / ".join(f"{y * 1e3:g}" for y in ZONE_Y0) + f" mm, x0 where |u| first exceeds {ZONE_U[0] * 1e3:g} "
            f"mm [mm], and the zone's width to |u| > {ZONE_U[1] * 1e3:g} mm [mm]: "
            + ("; ".join(f"{h * 1e3:g} mm x0 " + " / ".join(f"{r[0] * 1e3:.1f}" for r in rows) + ", width "
                         + " / ".join(f"{r[1] * 1e3:.1f}" for r in rows)
                         for h, rows in sorted(f.items(), reverse=True))
               or "no run with seeded centres"))


def stored_explicit(hs=None, store=REF.STORE) -> dict:
    """{h: (x, y, volume)} of the runs stored in store (default: every one, reference.stored_in) that have their
    points (reference.load_points)."""
    hs = REF.stored_in(store) if hs is None else hs
    return {h: REF.load_points(h, store) for h in hs if REF.points_path(h, store).exists()}


def stored_seeded(hs=None, store=REF.STORE) -> dict:
    """{h: (x0, y0)} the seeded centres of the runs stored in store that have them (reference.load_seeded)."""
    hs = REF.stored_in(store) if hs is None else hs
    out = {h: REF.load_seeded(h, store) for h in hs if REF.points_path(h, store).exists()}
    return {h: s for h, s in out.items() if s is not None}


if __name__ == "__main__":  # pragma: no cover
    runs = stored_explicit()
    for h in (0.01, 0.005):
        fr, _, _ = REF.run_explicit(h)
        runs[h] = tuple(fr[c].to_numpy(float) for c in ("x", "y", "volume"))
    print("\n".join(study(runs)))
