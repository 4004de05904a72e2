"""Is the fine Bui surface still converging, or run-sensitive? (issue 18, the equal-error reference)

The case's error measure is every run's final surface RMS against the finest stored explicit run (reference.py,
h = 0.625 mm when this study was written, 0.3125 mm since the twenty-ninth session). Its self-convergence slowed
below 1.25 mm (differences 10-5 / 5-2.5 / 2.5-1.25 / 1.25-0.625 / 0.625-0.3125 mm: 3.24 / 1.94 / 0.91 / 0.65 /
0.55 mm), so Richardson gave the reference a large own error and the goal row "implicit
within 2x explicit at equal error" stayed undetermined. A collapse is chaotic: if the surface at a fine h depends
on round-off-sized differences of the run by about as much as the last differences, those differences are run
noise, not discretisation error, and Richardson on single runs cannot separate them. This study measures it.

Ensemble: the explicit case scene (reference.EXPLICIT_SCENE) at cell size h with gravity scaled by (1 + k EPS),
k = 1, 2, ... (EPS = 1e-9: a perturbation far below any physical effect, 5e6 ulps of g, that a chaotic run
amplifies); member k = 0 is the stored reference run itself (reference.py, the unperturbed scene; checked bitwise
by `run ... 0`). Per measure of surface_study.py (the case's max per bin of h, 5 mm bins, thickness profiles) and h:
  - spread: the RMS over REF_X of the members' standard deviation (the run noise of ONE run at that h);
  - the ensemble mean's self-convergence (differences of the means of successive h) and each mean's distance to
    the finest mean, with the noise the means still carry (spread / sqrt(members)).
Stored: reference_runs/mpm_bui_implicit/ensemble/explicit_h<h>mm_k<k>.npz (final point centres and volumes,
float64, and the provenance: command, commit, date, wall time, load). A study, not a check: no rows.
Reproduce: `python -m validation.cases.mpm_bui_implicit.ensemble run H K [K ...] [--threads N] [--out folder]`, then
`python -m validation.cases.mpm_bui_implicit.ensemble report`."""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from validation.cases.mpm_bui_implicit import reference as REF
from validation.cases.mpm_bui_implicit import surface_study as SS

EPS = 1e-9                    # relative gravity perturbation per member index k
K_ROUNDOFF = 1000             # members k < K_ROUNDOFF form the round-off ensemble; larger k (1e-6 .. 1e-2 of g)
                              # measure the response to the perturbation's size (linear: not chaotic)
STORE = REF.STORE / "ensemble"


def member_path(h: float, k: int, store: Path = STORE) -> Path:
    return Path(store) / f"explicit_h{h * 1000:g}mm_k{k}.npz"


def run_member(h: float, k: int, threads: int = 1):
    """(final particles frame, scene, wall s) of member k at cell size h: the scene's gravity x (1 + k EPS)."""
    ov = {}
    if k:
        from coupler.scene import load_scene
        ov["gravity"] = [float(c) * (1.0 + k * EPS) for c in load_scene(REF.EXPLICIT_SCENE).gravity]
    return REF.run_explicit(h, threads=threads, overrides=ov)


def write_member(h: float, k: int, threads: int = 1, store: Path = STORE) -> Path:
    import os
    load0 = os.getloadavg()
    fr, scene, wall = run_member(h, k, threads)
    load1 = os.getloadavg()
    commit = REF.commit_id()
    meta = (f"Bui collapse, explicit native MPM, h = {h * 1000:g} mm, member k = {k} (gravity x (1 + {k} x {EPS:g})), "
            f"{len(fr)} points, t = {scene.time.t_end:g} s, {threads} numba thread(s); command: python -m "
            f"validation.cases.mpm_bui_implicit.ensemble run {h:g} {k}; commit {commit}, "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, wall {wall:.1f} s (1-min load {load0[0]:.1f} at "
            f"start / {load1[0]:.1f} at end); volume change {REF.frame_volume_change(fr, scene):+.5f}")
    Path(store).mkdir(parents=True, exist_ok=True)
    p = member_path(h, k, store)
    np.savez_compressed(p, x=fr["x"].to_numpy(float), y=fr["y"].to_numpy(float),
                        volume=fr["volume"].to_numpy(float), meta=np.array(meta))
    return p


def load_members(store: Path = STORE) -> dict:
    """{h: {k: (x, y, volume)}}: the stored members (every k), with k = 0 the stored reference runs
    (reference.load_points: every stored one, surface_study.stored_explicit)."""
    out: dict = {}
    for f in sorted(Path(store).glob("explicit_h*mm_k*.npz")):
        hs, ks = f.stem[len("explicit_h"):].split("mm_k")
        h = round(float(hs) / 1000.0, 9)
        with np.load(f) as z:
            out.setdefault(h, {})[int(ks)] = (z["x"], z["y"], z["volume"])
    for h, pts in SS.stored_explicit().items():     # member 0 of every stored reference run, with members or not
        out.setdefault(round(h, 9), {}).setdefault(0, pts)
    return out


def stats(members: dict) -> dict:
    """Per measure name: {h: (n, mean profile on REF_X, spread = RMS_x of the members' std (ddof 1))}."""
    res: dict = {}
    for name, f in SS.MEASURES:
        per = {}
        for h, mem in members.items():
            P = np.array([f(*mem[k], h) for k in sorted(mem)])
            spread = float(math.sqrt(np.mean(P.var(axis=0, ddof=1)))) if len(P) > 1 else float("nan")
            per[h] = (len(P), P.mean(axis=0), spread, P)
        res[name] = per
    return res


def point_differences(members: dict) -> list[str]:
    """Per h: the largest distance of a round-off member's (0 < k < K_ROUNDOFF) final point centres from member 0's
    (same points, same order) and their RMS range; each larger perturbation on its own line, against its size
    k EPS: what the run does to a perturbation, point by point."""
    lines = []
    for h, mem in sorted(members.items(), reverse=True):
        x0, y0 = mem[0][0], mem[0][1]
        d = {k: np.hypot(mem[k][0] - x0, mem[k][1] - y0) for k in sorted(mem)[1:]}
        ro = [k for k in d if k < K_ROUNDOFF]
        if ro:
            rms_ = [math.sqrt(np.mean(d[k] ** 2)) for k in ro]
            lines.append(f"ensemble, final points vs member 0: h = {h * 1e3:g} mm, {len(ro)} round-off members (k = "
                         f"{', '.join(map(str, ro))}): max {max(d[k].max() for k in ro):.2e} m, RMS "
                         f"{min(rms_):.1e}-{max(rms_):.1e} m")
        for k in (k for k in d if k >= K_ROUNDOFF):
            lines.append(f"ensemble, final points vs member 0: h = {h * 1e3:g} mm, k = {k} (g x (1 + {k * EPS:.0e})): "
                         f"max {d[k].max():.2e} m, RMS {math.sqrt(np.mean(d[k] ** 2)):.2e} m")
    return lines


BANDS = ((0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4), (0.4, 0.5))     # [m] x bands of where_differences


def where_differences(members: dict) -> list[str]:
    """Where along x the self-convergence differences of member 0 (the stored runs) sit, with the case's measure:
    per band of BANDS the mean and RMS of s_h - s_h/2 (a systematic offset keeps its sign and is not run noise), and
    the furthest point (run-out, beyond REF_X's 0.5 m at the finest h)."""
    name, f = SS.MEASURES[0]
    hs = sorted((h for h in members if 0 in members[h]), reverse=True)
    prof = {h: f(*members[h][0], h) for h in hs}
    lines = [f"ensemble, where the differences sit ({name}, member 0): furthest point "
             + ", ".join(f"{h * 1e3:g} mm {members[h][0][0].max():.3f} m" for h in hs)]
    X = REF.REF_X
    for a, b in zip(hs, hs[1:]):
        d = prof[a] - prof[b]
        parts = []
        for lo, hi in BANDS:
            m = (X >= lo) & (X < hi)
            parts.append(f"[{lo:g}, {hi:g}) m: mean {d[m].mean() * 1e3:+.2f} / RMS {SS.rms(d[m]) * 1e3:.2f} "
                         f"({np.sum(d[m] ** 2) / np.sum(d * d):.0%})")
        lines.append(f"ensemble, s({a * 1e3:g} mm) - s({b * 1e3:g} mm) [mm] (RMS {SS.rms(d) * 1e3:.2f}): " + "; ".join(parts))
    return lines


def case_metrics(members: dict) -> list[str]:
    """The Bui case's own metrics (bui_metrics: failure-line angle, run-out, toe height, surface RMS against the
    experiment) of member 0 at every stored h: which of them converge with h and which do not. The initial point
    positions (for the displacements the failure line needs) are those the solver seeds for the scene at h."""
    import pandas as pd

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene
    from validation.cases.mpm_bui_collapse.metrics import bui_metrics
    parts = []
    for h in sorted((h for h in members if 0 in members[h]), reverse=True):
        scene = load_scene(REF.EXPLICIT_SCENE, overrides={"mpm.grid.cell_size": h})
        f0 = MPMSolver(scene).particles_frame()
        x, y, v = members[h][0]
        m = bui_metrics(pd.DataFrame({"x": x, "y": y, "ux": x - f0["x"].to_numpy(float),
                                      "uy": y - f0["y"].to_numpy(float), "volume": v}), scene)
        parts.append(f"{h * 1e3:g} mm: failure line {m['angle']:.2f} deg, run-out {m['runout']:.4f} m, toe "
                     f"{m['toe'] * 1e3:.2f} mm, surface RMS vs experiment {m['rms'] * 1e3:.2f} mm")
    return ["ensemble, the case's metrics of member 0 (bui_metrics): " + "; ".join(parts)]


def report(members: dict) -> list[str]:
    """The study's lines: the point differences of every member, then for the round-off ensemble (k < K_ROUNDOFF)
    per measure and h the spread of one run, the means' self-convergence and distances to the finest mean."""
    lines = point_differences(members) + where_differences(members) + case_metrics(members)
    members = {h: {k: v for k, v in mem.items() if k < K_ROUNDOFF} for h, mem in members.items()}
    lines += [f"ensemble study (ensemble.py): round-off members (k < {K_ROUNDOFF}) per h " + ", ".join(
        f"{h * 1e3:g} mm: {len(m)} (k = {', '.join(str(k) for k in sorted(m))})" for h, m in sorted(members.items(), reverse=True))
        + f"; gravity x (1 + k {EPS:g}); RMS on {len(REF.REF_X)} points x in [0, {REF.X_MAX_REF:g}] m"]
    for name, per in stats(members).items():
        hs = sorted(per, reverse=True)
        fine = hs[-1]
        parts = []
        for h in hs:
            n, mean, spread, P = per[h]
            d_ref = SS.rms(mean - per[fine][1]) if h != fine else float("nan")
            # pairwise member differences (what a run-against-run comparison at one h sees)
            pw = [SS.rms(P[i] - P[j]) for i in range(n) for j in range(i + 1, n)]
            parts.append(f"{h * 1e3:g} mm: spread {spread * 1e6:.3f} um, member pairs {min(pw) * 1e6:.3f}-"
                         f"{max(pw) * 1e6:.3f} um" if pw else f"{h * 1e3:g} mm: 1 member")
            if h != fine:
                parts[-1] += f", mean vs the {fine * 1e3:g} mm mean {d_ref * 1e3:.2f} mm"
        dm = [SS.rms(per[a][1] - per[b][1]) for a, b in zip(hs, hs[1:])]
        lines.append(f"ensemble, {name}: " + "; ".join(parts) + "; means' self-convergence "
                     + " / ".join(f"{a * 1e3:g}-{b * 1e3:g}" for a, b in zip(hs, hs[1:])) + " mm: "
                     + " / ".join(f"{x * 1e3:.2f}" for x in dm) + " mm")
    return lines


if __name__ == "__main__":  # pragma: no cover
    import argparse
    ap = argparse.ArgumentParser(description="perturbed explicit Bui runs: is the fine surface run-sensitive?")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run and store members k at cell size h")
    r.add_argument("h", type=float)
    r.add_argument("k", type=int, nargs="+")
    r.add_argument("--threads", type=int, default=1)
    r.add_argument("--out", default=str(STORE), help=f"folder (default {STORE})")
    sub.add_parser("report", help="print the study from the stored members")
    a = ap.parse_args()
    if a.cmd == "run":
        for k in a.k:
            print(write_member(a.h, k, a.threads, Path(a.out)), flush=True)
    else:
        print("\n".join(report(load_members())))
