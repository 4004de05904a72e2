"""Is the fine Bui surface still converging, or run-sensitive? (issue 18, the equal-error reference)

The case's error measure is every run's final surface RMS against the finest stored explicit run (reference.py,
h = 0.625 mm). Its self-convergence slowed below 1.25 mm (differences 10-5 / 5-2.5 / 2.5-1.25 / 1.25-0.625 mm:
3.24 / 1.94 / 0.91 / 0.65 mm), so Richardson gave the reference a large own error and the goal row "implicit
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
Reproduce: `python -m validation.cases.mpm_bui_implicit.ensemble run H K [K ...] [--threads N]`, then
`python -m validation.cases.mpm_bui_implicit.ensemble report`."""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from validation.cases.mpm_bui_implicit import reference as REF
from validation.cases.mpm_bui_implicit import surface_study as SS

EPS = 1e-9                    # relative gravity perturbation per member index k
G = 9.81                      # [m/s^2] the scene's |g| (scene.toml), scaled per member
STORE = REF.STORE / "ensemble"


def member_path(h: float, k: int, store: Path = STORE) -> Path:
    return Path(store) / f"explicit_h{h * 1000:g}mm_k{k}.npz"


def run_member(h: float, k: int, threads: int = 1):
    """(final particles frame, scene, wall s) of member k at cell size h (gravity (1 + k EPS) g)."""
    import numba

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene
    numba.set_num_threads(threads)
    ov = {"mpm.grid.cell_size": h}
    if k:
        ov["gravity"] = [0.0, -G * (1.0 + k * EPS), 0.0]
    scene = load_scene(REF.EXPLICIT_SCENE, overrides=ov)
    sol = MPMSolver(scene)
    t0 = time.perf_counter()
    sol.advance_to(scene.time.t_end)
    return sol.particles_frame(), scene, time.perf_counter() - t0


def write_member(h: float, k: int, threads: int = 1, store: Path = STORE) -> Path:
    import os
    import subprocess
    load0 = os.getloadavg()
    fr, scene, wall = run_member(h, k, threads)
    load1 = os.getloadavg()
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REF.ROOT, capture_output=True, text=True).stdout.strip()
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
    """{h: {k: (x, y, volume)}}: the stored members, with k = 0 the stored reference run (reference.load_points)."""
    out: dict = {}
    for f in sorted(Path(store).glob("explicit_h*mm_k*.npz")):
        hs, ks = f.stem[len("explicit_h"):].split("mm_k")
        h = round(float(hs) / 1000.0, 9)
        with np.load(f) as z:
            out.setdefault(h, {})[int(ks)] = (z["x"], z["y"], z["volume"])
    for h in out:
        if 0 not in out[h] and REF.points_path(h).exists():
            out[h][0] = REF.load_points(h)
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


def report(members: dict) -> list[str]:
    """The study's lines: per measure and h the spread of one run, the means' self-convergence and distances to the
    finest mean (with the noise left in the means)."""
    lines = [f"ensemble study (ensemble.py): members per h " + ", ".join(
        f"{h * 1e3:g} mm: {len(m)} (k = {', '.join(str(k) for k in sorted(m))})" for h, m in sorted(members.items(), reverse=True))
        + f"; gravity x (1 + k {EPS:g}); RMS on {len(REF.REF_X)} points x in [0, {REF.X_MAX_REF:g}] m [mm]"]
    for name, per in stats(members).items():
        hs = sorted(per, reverse=True)
        fine = hs[-1]
        parts = []
        for h in hs:
            n, mean, spread, P = per[h]
            d_ref = SS.rms(mean - per[fine][1]) if h != fine else float("nan")
            # pairwise member differences (what a run-against-run comparison at one h sees)
            pw = [SS.rms(P[i] - P[j]) for i in range(n) for j in range(i + 1, n)]
            parts.append(f"{h * 1e3:g} mm: spread {spread * 1e3:.2f}, member pairs {min(pw) * 1e3:.2f}-"
                         f"{max(pw) * 1e3:.2f}" if pw else f"{h * 1e3:g} mm: 1 member")
            if h != fine:
                parts[-1] += f", mean vs the {fine * 1e3:g} mm mean {d_ref * 1e3:.2f}"
        dm = [SS.rms(per[a][1] - per[b][1]) for a, b in zip(hs, hs[1:])]
        lines.append(f"ensemble, {name}: " + "; ".join(parts) + "; means' self-convergence "
                     + " / ".join(f"{a * 1e3:g}-{b * 1e3:g}" for a, b in zip(hs, hs[1:])) + " mm: "
                     + " / ".join(f"{x * 1e3:.2f}" for x in dm))
    return lines


if __name__ == "__main__":  # pragma: no cover
    import argparse
    ap = argparse.ArgumentParser(description="perturbed explicit Bui runs: is the fine surface run-sensitive?")
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run and store members k at cell size h")
    r.add_argument("h", type=float)
    r.add_argument("k", type=int, nargs="+")
    r.add_argument("--threads", type=int, default=1)
    sub.add_parser("report", help="print the study from the stored members")
    a = ap.parse_args()
    if a.cmd == "run":
        for k in a.k:
            print(write_member(a.h, k, a.threads), flush=True)
    else:
        print("\n".join(report(load_members())))
