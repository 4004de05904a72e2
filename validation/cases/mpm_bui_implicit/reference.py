"""Converged numerical reference of the Bui collapse's final free surface (issue 18): a fine EXPLICIT run of the
explicit case's scene (validation/cases/mpm_bui_collapse/scene.toml) at cell size h, one numba thread, to t_end.
Its surface s_ref(x) (the case's definition: per bin of width h the highest point centre + half a point,
bui_metrics / validation.metrics.surface_profile) is the reference of the speed-against-error chart of
mpm_bui_implicit: the surface RMS of a run against it is taken on REF_X (uniform, 0 .. X_MAX_REF), where every
run's and the reference's surface is read by linear interpolation between bin centres.

Stored: reference_runs/mpm_bui_implicit/explicit_h<h>mm.csv (x bin centre, surface height; header with the
command, commit, date, wall time, load and point count) and explicit_h<h>mm_points.npz (the final point centres and
volumes, float64, for surface_study.py). The finest stored run of a variant is its reference (STORED; Mohr-Coulomb:
h = 0.3125 mm since the twenty-ninth session, 84 min on 2 threads of the Zen 5 host; h = 0.625 mm from the tenth
session, 1.25 mm before; mu(I): 0.625 mm; at the explicit scene's cfl 0.5 every one reaches t_end with no point
lost; since the thirtieth session also a Mohr-Coulomb sequence with the step refined, --cfl 0.125, in
reference_runs/mpm_bui_implicit/cfl0.125: STORED; its 0.3125 mm run, thirty-second session: 5.6 h on 2 threads of
the Zen 5 host, in three segments from checkpoints); the coarser ones, with the case's own 10 and 5 mm runs, give the
differences of successive halvings from which the case estimates a sequence's own error (own_error_tail), and the
case takes the finest run of the sequence whose estimate is smallest (best_candidate: since the thirty-second
session the 0.3125 mm run at cfl 0.5, 3.01 mm, against the 0.3125 mm one at cfl 0.125, 3.02 mm; in the thirtieth and
thirty-first the 0.625 mm run at cfl 0.125, 1.18 mm from the four differences then stored).
Reproduce: `python -m validation.cases.mpm_bui_implicit.reference 0.0003125 0.000625 0.00125 0.0025 [--threads 2]
[--variant mu_i] [--cfl 0.125] [--out folder]` (the mu(I) variant into reference_runs/mpm_bui_implicit/mu_i/, the
refined step into .../cfl0.125/; the cfl 0.125 sequence: 0.000625 0.00125 0.0025 0.005 0.01 --cfl 0.125).
A run of hours takes --checkpoints DIR (since the thirty-first session): its state is saved there every
--checkpoint-every s (default 1800) and the same command resumes from it, bitwise as if never stopped, at the same
commit only; the header then lists the segments (MPMSolver.save_checkpoint; tests/mpm/test_mpm_checkpoint.py).
(tests/validation/test_bui_reference.py: the stored files' provenance and points; with MPMDEM_REFERENCE_CHECK=1 it
reruns the 2.5 mm one by that command and compares the surface and points)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
EXPLICIT_SCENE = ROOT / "validation" / "cases" / "mpm_bui_collapse" / "scene.toml"
STORE = ROOT / "reference_runs" / "mpm_bui_implicit"
# the material variants of the comparison: the case's rate-independent Mohr-Coulomb, and the same collapse with the
# mu(I) rate-dependent friction of mpm_bui_collapse (MU_I), whose surface converges with h where MC's does not
# (twenty-third session); a variant's runs are stored in STORE / <variant> ("mc": STORE itself)
VARIANTS = ("mc", "mu_i")


def _check_variant(variant: str) -> None:
    if variant not in VARIANTS:
        raise ValueError(f"variant: must be one of {', '.join(VARIANTS)}, got {variant!r}")


def _check_cfl(cfl: float | None) -> None:
    """A refined step's cfl (None: the scene's own): in (0, 1], the explicit scene's own bounds."""
    if cfl is not None and not 0.0 < cfl <= 1.0:
        raise ValueError(f"cfl: must be in (0, 1], got {cfl:g}")


def variant_overrides(variant: str) -> dict:
    """The scene overrides of a material variant ({} for the case's own Mohr-Coulomb)."""
    _check_variant(variant)
    if variant == "mu_i":
        from validation.cases.mpm_bui_collapse.case import MU_I
        return dict(MU_I)
    return {}


# the stored runs, by sequence (material variant, cfl of the step: None = the explicit scene's own 0.5), their cell
# sizes finest first. The finest run of a sequence is its candidate reference, the others (and, at the scene's cfl,
# the case's own 10 and 5 mm runs) give the differences of successive halvings. Mohr-Coulomb at the scene's cfl
# down to 0.3125 mm (twenty-ninth session; its surface converges slowly, the case's rows); Mohr-Coulomb with the
# step refined to cfl 0.125 (thirtieth session: at a fixed h the surface moves with dt at first order, as much as
# the last halvings of h at cfl 0.5 did), every level stored, down to 0.3125 mm since the thirty-second session;
# mu(I) at the scene's cfl down to 0.625 mm
STORED = {("mc", None): (0.0003125, 0.000625, 0.00125, 0.0025),
          ("mc", 0.125): (0.0003125, 0.000625, 0.00125, 0.0025, 0.005, 0.01),
          ("mu_i", None): (0.000625, 0.00125, 0.0025)}


def stored_hs(variant: str, cfl: float | None = None) -> tuple:
    """The cell sizes of a sequence's stored runs, finest first (STORED; () for a sequence not stored)."""
    _check_variant(variant)
    return STORED.get((variant, cfl), ())


def sequences(variant: str) -> list:
    """The cfl values of a variant's stored sequences (None: the scene's own), the scene's own first."""
    _check_variant(variant)
    return sorted((c for v, c in STORED if v == variant), key=lambda c: -1.0 if c is None else c)


def stored_in(store: Path) -> list[float]:
    """The cell sizes of the runs stored in `store` (their csv files, explicit_h<h>mm.csv), finest first."""
    return sorted(float(f.name[len("explicit_h"):-len("mm.csv")]) / 1000.0
                  for f in Path(store).glob("explicit_h*mm.csv"))


def store_of(variant: str, cfl: float | None = None) -> Path:
    """The folder of a variant's stored runs: at the explicit scene's own cfl (0.5) by default, or of the runs with
    the step refined to `cfl` (its subfolder cfl<cfl>: the time-refined sequence, thirtieth session)."""
    _check_variant(variant)
    base = STORE if variant == "mc" else STORE / variant
    return base if cfl is None else base / f"cfl{cfl:g}"


X_MAX_REF = 0.5          # surface error over x in [0, 0.5] m (the deposit: run-out 0.41-0.49 m)
REF_X = np.linspace(0.0, X_MAX_REF, 501)


def build_explicit(h: float, t_end: float | None = None, threads: int = 1, overrides: dict | None = None):
    """(solver, scene) of the explicit case scene at cell size h on `threads` numba threads (the explicit MPM is
    bitwise identical for any thread count); overrides: further scene overrides (ensemble.py's perturbed gravity)."""
    import numba

    from coupler.mpm.solver import MPMSolver
    from coupler.scene import load_scene
    numba.set_num_threads(threads)
    ov = {"mpm.grid.cell_size": h, **(overrides or {})}
    if t_end is not None:
        ov["time.t_end"] = t_end
    scene = load_scene(EXPLICIT_SCENE, overrides=ov)
    return MPMSolver(scene), scene


def run_explicit(h: float, t_end: float | None = None, threads: int = 1, overrides: dict | None = None):
    """(final particles frame, scene, wall s) of the explicit case scene at cell size h (build_explicit)."""
    sol, scene = build_explicit(h, t_end, threads, overrides)
    t0 = time.perf_counter()
    sol.advance_to(scene.time.t_end)
    return sol.particles_frame(), scene, time.perf_counter() - t0


CHECKPOINT_EVERY = 1800.0     # s of wall time between two checkpoints of a resumable run (advance_checkpointed)


def _host() -> str:
    try:
        return next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        import platform
        return platform.processor() or "unknown"


def advance_checkpointed(sol, t_end: float, checkpoint: Path | None = None, every: float = CHECKPOINT_EVERY,
                         commit: str = "unknown") -> list[dict]:
    """Advance a fresh solver to t_end as sol.advance_to does (k = ceil(t_end / dt) equal steps of t_end / k; the
    same bits), saving its state to `checkpoint` (MPMSolver.save_checkpoint) every `every` s of wall time and,
    if that file exists, resuming from it first: a run of hours survives a stopped process. A checkpoint written
    at another commit is refused (ValueError): the stored run names one commit. Returns the segments, one per
    process that worked on the run (host, commit, start UTC, steps from / to, wall s, 1-min load at start / end)."""
    import os
    k = max(1, int(math.ceil(t_end / sol.dt - 1e-9)))
    dt = t_end / k
    segments = []
    if checkpoint is not None and Path(checkpoint).exists():
        def same_commit(meta):
            if meta.get("commit") != commit:
                raise ValueError(f"checkpoint {checkpoint}: written at commit {meta.get('commit')}, the code is at "
                                 f"{commit}; check that commit out to resume, or delete the checkpoint to start again")

        meta = sol.load_checkpoint(checkpoint, same_commit)
        segments = list(meta["segments"])
    seg = {"host": _host(), "commit": commit, "start": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "from_step": sol.nstep, "to_step": sol.nstep, "wall_s": 0.0, "load": [os.getloadavg()[0], None]}
    t0 = saved = time.perf_counter()
    while sol.nstep < k:
        sol.advance(min(k - sol.nstep, 200), dt=dt)
        now = time.perf_counter()
        seg.update(to_step=sol.nstep, wall_s=now - t0)
        if checkpoint is not None and now - saved >= every and sol.nstep < k:
            seg["load"][1] = os.getloadavg()[0]
            sol.save_checkpoint(checkpoint, {"commit": commit, "steps": k, "segments": segments + [seg]})
            saved = time.perf_counter()
    sol.t = float(t_end)
    seg.update(wall_s=time.perf_counter() - t0, load=[seg["load"][0], os.getloadavg()[0]])
    return segments + [seg]


def surface_of(frame, scene):
    """(bin centres, surface) of a final frame with the case's definition (half-point lift, bins of h)."""
    from validation.cases.mpm_bui_collapse.metrics import surface
    h = scene.mpm.cell_size
    ppc = scene.mpm.bodies[0].particles_per_cell
    return surface(frame["x"].to_numpy(float), frame["y"].to_numpy(float), h, 0.5 * h / ppc,
                   float(scene.mpm.size[0]))


def rms_against(xc, top, xr, sr) -> float:
    """Surface RMS of (xc, top) against the reference (xr, sr) on REF_X (linear interpolation of both)."""
    d = np.interp(REF_X, xc, top) - np.interp(REF_X, xr, sr)
    return float(math.sqrt(np.mean(d * d)))


def path(h: float, store: Path = STORE, suffix: str = ".csv") -> Path:
    """The stored reference file at cell size h: the surface (.csv) or, with suffix "_points.npz", its points."""
    return Path(store) / f"explicit_h{h * 1000:g}mm{suffix}"


def _existing(f: Path) -> Path:
    if not f.exists():
        raise OSError(f"no stored reference {f}")
    return f


def load(h: float, store: Path = STORE):
    """(x, s) of the stored reference at cell size h (in store)."""
    f = _existing(path(h, store))
    rows = [ln.split(",") for ln in f.read_text().splitlines()
            if ln and not ln.startswith("#") and not ln.startswith("x_m")]      # '#' lines, column names, data
    a = np.array(rows, float)
    return a[:, 0], a[:, 1]


def commit_id() -> str:
    """The checked-out commit (provenance of a stored run), "unknown" without git."""
    import subprocess
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        return "unknown"


def checkpoint_path(h: float, folder: Path, variant: str = "mc", cfl: float | None = None) -> Path:
    """The checkpoint file of the run (h, variant, cfl) in `folder` (write(..., checkpoints=folder))."""
    return Path(folder) / (f"explicit_h{h * 1000:g}mm_{variant}" + ("" if cfl is None else f"_cfl{cfl:g}")
                           + ".ckpt.pkl")


def write(h: float, store: Path = STORE, threads: int = 1, variant: str = "mc", cfl: float | None = None,
          checkpoints: Path | None = None, every: float = CHECKPOINT_EVERY) -> Path:
    """Run the explicit scene at cell size h (material variant, and the step refined to `cfl` if given) and store
    its surface and final points in store. checkpoints: a folder for the run's checkpoint (checkpoint_path), saved
    every `every` s and resumed from if there (advance_checkpointed); deleted once the run is stored."""
    import os
    _check_cfl(cfl)
    ov = variant_overrides(variant)
    if cfl is not None:
        ov["mpm.cfl"] = cfl
    sol, scene = build_explicit(h, threads=threads, overrides=ov)
    commit = commit_id()
    ckpt = None if checkpoints is None else checkpoint_path(h, checkpoints, variant, cfl)
    segs = advance_checkpointed(sol, scene.time.t_end, ckpt, every, commit)
    fr = sol.particles_frame()
    wall = sum(sg["wall_s"] for sg in segs)
    xc, top = surface_of(fr, scene)
    Path(store).mkdir(parents=True, exist_ok=True)
    p = path(h, store)
    law = "" if variant == "mc" else f", material variant {variant} ({variant_overrides(variant)})"
    opt = ("" if variant == "mc" else f" --variant {variant}") + ("" if cfl is None else f" --cfl {cfl:g}")
    hdr = (f"# Bui collapse final surface, EXPLICIT native MPM, h = {h * 1000:g} mm, cfl {scene.mpm.cfl:g}, "
           f"{len(fr)} points, t = {scene.time.t_end:g} s, {threads} numba thread{'s' if threads > 1 else ''}{law}\n"
           f"# command: python -m validation.cases.mpm_bui_implicit.reference {h:g}{opt}\n"
           f"# commit {commit}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, wall {wall:.1f} s "
           f"(nice {os.nice(0)}, shared machine, 1-min load {segs[0]['load'][0]:.1f} at start / "
           f"{segs[-1]['load'][1]:.1f} at end)\n"
           + ("" if len(segs) == 1 else
              f"# run in {len(segs)} segments, each from the checkpoint the one before saved (wall: theirs summed)\n"
              + "".join(f"# segment {i + 1}: {sg['start']}, steps {sg['from_step']}-{sg['to_step']}, wall "
                        f"{sg['wall_s']:.1f} s, load {sg['load'][0]:.1f} / {sg['load'][1]:.1f}, {sg['host']}\n"
                        for i, sg in enumerate(segs))) +
           f"# volume change {frame_volume_change(fr, scene):+.5f}\nx_m,surface_m\n")
    with open(p, "w") as f:
        f.write(hdr)
        for a, b in zip(xc, top):
            f.write(f"{a:.9f},{b:.9f}\n")
    # the final point centres too (float64, bitwise): the alternative error measures of surface_study.py need the
    # points, not only the surface
    # and, since the thirtieth session, their seeded centres x0 = x - ux, y0 = y - uy (do the points still sample the
    # deformation? validation.metrics.lattice_triangles)
    x, y = fr["x"].to_numpy(float), fr["y"].to_numpy(float)
    np.savez_compressed(points_path(h, store), x=x, y=y, volume=fr["volume"].to_numpy(float),
                        x0=x - fr["ux"].to_numpy(float), y0=y - fr["uy"].to_numpy(float))
    if ckpt is not None:
        ckpt.unlink(missing_ok=True)
    return p


def points_path(h: float, store: Path = STORE) -> Path:
    return path(h, store, "_points.npz")


def load_points(h: float, store: Path = STORE):
    """(x, y, volume) of the final points of the stored reference run at cell size h (written with its csv)."""
    with np.load(_existing(points_path(h, store))) as z:
        return z["x"], z["y"], z["volume"]


def load_seeded(h: float, store: Path = STORE):
    """(x0, y0) the seeded centres of the stored run's final points (in the order of load_points), or None for a run
    stored before they were (before the thirtieth session)."""
    with np.load(_existing(points_path(h, store))) as z:
        return (z["x0"], z["y0"]) if "x0" in z.files else None


def richardson_order(h2, h1, h0, q):
    """p with (h2^p - h0^p) / (h1^p - h0^p) = q (h2 > h1 > h0: errors of two runs against a finer reference
    h0, e(h) = C (h^p - h0^p)); NaN when q is outside what p in (0.05, 5) gives."""
    f = lambda p: (h2 ** p - h0 ** p) / (h1 ** p - h0 ** p) - q
    lo, hi = 0.05, 5.0
    if not (f(lo) < 0.0 < f(hi)):
        return float("nan")
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < 0.0 else (lo, mid)
    return 0.5 * (lo + hi)


def own_error(h2: float, h1: float, h0: float, e2: float, e1: float) -> tuple[float, float]:
    """(p, own error C h0^p) of a reference at h0 from the errors e2, e1 of two runs h2 > h1 > h0 against it
    (Richardson with e(h) = C (h^p - h0^p)); (NaN, NaN) when no order in (0.05, 5) fits."""
    p = richardson_order(h2, h1, h0, e2 / e1)
    if not np.isfinite(p):
        return float("nan"), float("nan")
    return p, e1 / (h1 ** p - h0 ** p) * h0 ** p


def own_error_tail(diffs) -> tuple[float, float]:
    """(r, bound) from the surface RMS differences of successive halvings d_k = |s(h_k) - s(h_k / 2)|, coarse to
    fine, the last one that of the run at twice the reference's cell size against the reference: r = the largest
    ratio d_(k+1) / d_k observed, bound = d_last r / (1 - r), the reference's own error if the differences the finer
    runs would add keep shrinking at least at that rate (the triangle inequality over |s(h0 / 2^k) - s(h0 / 2^(k+1))|
    = d_last r^(k+1)); (NaN, NaN) with fewer than two differences or r >= 1 (no decay seen: no estimate).
    Unlike own_error (Richardson on the errors against the reference) it does not assume that the error keeps one
    shape as h shrinks: with e(h) = C (h^p - h0^p) phi the two agree; when the error's shape changes with h the
    errors against the reference add up less than that model assumes, and own_error reads that as a low order and
    a large own error (Bui, Mohr-Coulomb: p = 0.13 and 6.6 mm, where the differences it implies would shrink by 9 %
    per halving, and they shrink by 29-53 %; mu(I): no order fits at all while the differences halve)."""
    d = [float(x) for x in diffs]
    if len(d) < 2 or min(d[:-1]) <= 0.0:
        return float("nan"), float("nan")
    r = max(b / a for a, b in zip(d, d[1:]))
    if not r < 1.0:
        return float("nan"), float("nan")
    return r, d[-1] * r / (1.0 - r)


@dataclass(frozen=True)
class Candidate:
    """A stored sequence as a candidate reference: its finest run (h; surface x, s = surfaces[h]) and the differences
    of successive halvings down to it (levels h_0 > h_0 / 2 > ... > h, diffs; own_error_tail: r, own)."""
    variant: str
    cfl: float | None          # None: the explicit scene's own cfl
    h: float
    surfaces: dict             # {h: (x, s)} of every level, the reference's included
    levels: tuple
    diffs: tuple
    r: float
    own: float

    @property
    def x(self) -> np.ndarray:
        """The reference's bin centres (its surfaces entry)."""
        return self.surfaces[self.h][0]

    @property
    def s(self) -> np.ndarray:
        """The reference's surface heights."""
        return self.surfaces[self.h][1]

    @property
    def store(self) -> Path:
        return store_of(self.variant, self.cfl)

    @property
    def label(self) -> str:
        return f"explicit h={self.h * 1000:g} mm, cfl {'0.5 (the scene)' if self.cfl is None else f'{self.cfl:g}'}"


def candidate(variant: str, cfl: float | None = None, coarse: dict | None = None, store: Path | None = None):
    """The Candidate of a stored sequence (None when nothing is stored). coarse: {h: (x, s)} of runs of the same
    sequence made elsewhere (the case's own explicit runs, at the scene's cfl), used for the levels not stored."""
    store = store_of(variant, cfl) if store is None else store
    hs = stored_in(store)
    if not hs:
        return None
    surf = {h: load(h, store) for h in hs}
    for h, xs in (coarse or {}).items():
        surf.setdefault(h, xs)
    ref_h = hs[0]
    levels = [ref_h]
    for h in sorted(h for h in surf if h > ref_h):
        if abs(h - 2.0 * levels[0]) < 1e-9 * h:
            levels.insert(0, h)
    diffs = tuple(rms_against(*surf[a], *surf[b]) for a, b in zip(levels, levels[1:]))
    r, own = own_error_tail(diffs)
    return Candidate(variant, cfl, ref_h, surf, tuple(levels), diffs, r, own)


def best_candidate(variant: str, coarse: dict | None = None):
    """(the reference, every candidate) of a variant: of its stored sequences (sequences) the one whose estimated own
    error (own_error_tail) is smallest; a sequence without an estimate (NaN) is chosen only if none has one. coarse:
    the case's runs at the scene's cfl (candidate). (None, []) with nothing stored."""
    cands = [c for c in (candidate(variant, cfl, coarse if cfl is None else None) for cfl in sequences(variant))
             if c is not None]
    if not cands:
        return None, []
    return min(cands, key=lambda c: (not np.isfinite(c.own), c.own if np.isfinite(c.own) else 0.0)), cands


def frame_volume_change(fr, scene) -> float:
    from validation.metrics import scene_mpm_body_extent
    lo, hi = scene_mpm_body_extent(scene)
    return float(fr["volume"].sum()) / float((hi[0] - lo[0]) * (hi[1] - lo[1])) - 1.0


if __name__ == "__main__":  # pragma: no cover
    import argparse
    ap = argparse.ArgumentParser(description="fine explicit Bui runs: the converged surface reference")
    ap.add_argument("h", nargs="+", type=float, help="cell sizes [m]")
    ap.add_argument("--variant", default="mc", choices=VARIANTS, help="material variant (default mc)")
    ap.add_argument("--out", default=None, help=f"folder (default {STORE}, or its subfolder <variant>)")
    ap.add_argument("--threads", type=int, default=1, help="numba threads (results are the same bitwise)")
    ap.add_argument("--cfl", type=float, default=None,
                    help="refine the step: dt = cfl h / c, in (0, 1] (default the scene's 0.5; stored in cfl<cfl>/)")
    ap.add_argument("--checkpoints", default=None,
                    help="folder for a checkpoint of each run, saved every --checkpoint-every s and resumed from "
                         "when there (the run then continues bitwise; deleted once the run is stored)")
    ap.add_argument("--checkpoint-every", type=float, default=CHECKPOINT_EVERY,
                    help=f"s of wall time between two checkpoints (default {CHECKPOINT_EVERY:g})")
    a = ap.parse_args()
    try:
        _check_cfl(a.cfl)
    except ValueError as e:
        ap.error(f"--{e}")
    if not a.checkpoint_every > 0.0:
        ap.error(f"--checkpoint-every: must be > 0 s, got {a.checkpoint_every:g}")
    for h in a.h:
        try:
            print(write(h, Path(a.out) if a.out else store_of(a.variant, a.cfl), a.threads, a.variant, a.cfl,
                        None if a.checkpoints is None else Path(a.checkpoints), a.checkpoint_every))
        except ValueError as e:           # a checkpoint of another scene or commit: one line, exit 2
            ap.error(str(e))
