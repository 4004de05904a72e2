"""Coupled segmental retaining wall (issue 15; Bui et al. 2014 geometry): six DEM blocks (rigid clusters of 6 x 5
spheres, each course 1.2 cm behind the one below) backfilled with an MPM body (plane-strain Mohr-Coulomb, Bui 2008
aluminium-bar parameters), fixed MPM base, slip left wall, DEM floor under the blocks. scene.toml is written by
make_scene.py (the header of the scene says every parameter and why).

Bringing the backfill to rest: the blocks held ([[dem.clusters]] motion = fixed until t_settle = 0.1 s), the
backfill stress-free at t = 0 and settling under its own weight against them, then the blocks released. Not the
geostatic initial stress: under the 1.2 cm treads each block overhangs it would carry the weight of backfill that
is not there (make_scene.py). The kinetic energy of the backfill at the release is reported (note).

Failure-mode checks (the experiment; per block k = 1 bottom .. 6 top, times after the release):
  * the wall moves rightwards and collapses: every block's final x displacement > 0 (rows per block, in the
    form -dx <= 0), and the top block ends at least its own height below its start (dy6 <= -H block);
  * the bottom block slides: final dx1 >= 10 mm, with max |rotation| < 5 deg;
  * the upper blocks translate and rotate: for k = 2..6 final dx >= 10 mm and max |rotation| >= 5 deg (the
    threshold the bottom block must stay below);
  * the blocks separate: the smallest final displacement of a block relative to the block below it (over the
    five joints) >= 5 mm (one sphere diameter: the resolution of the block outline).
Interface: the force the MPM receives equals the force the DEM puts on the wall (round-off); work of each side.
Resolution (RESOLUTION cell sizes; --full: RESOLUTION_FULL, run one by one: a run that stops is a failing row and
the grids are compared at the last output time all of them reached): wall time against the block final-centroid
change relative to the finest grid; stability across the two finest: max over blocks of the final-centroid distance /
wall height <= STABLE_TOL = 5 % (the goal of the cross-code comparison of xval_retaining_wall); the coupled
ensemble's own spread (std of the final centroids) is stated beside it, since a difference below the spread a
1e-3 perturbation of the coupling step produces cannot be resolved by one run per grid.
Ensembles (N_ENSEMBLE coupling-step perturbations dt (1 - k 1e-3), k = 0..N-1 (through coupling.dt; downwards as
ensembles.py does), on the ENSEMBLE_CELL grid):
per block the mean and std of the final x, y and rotation; compared with the DEM-only native ensemble of
xval_retaining_wall (wall.toml, settle-then-release) with validation/ensembles.compare_ensembles: z = |mean_a -
mean_b| / sqrt(std_a^2/n_a + std_b^2/n_b) <= 2 (informative rows: the two models differ in their backfill, so a
difference is a finding, not a bug); the DEM-only ensemble runs with --full only (N x ~50 s).
Performance (notes, perf_note): production run wall time against the issue's 60 s goal (with the load average: the
machine is shared), split into solvers (MPM / DEM / coupling own, summary.json cost_s), output at the output times
(cost_s.output), the writes after the run (tables + ParaView series) and the rest; the MPM and DEM steps and the
sub-step ratio. Output: MPM snapshots every 50 ms ([output] particles_interval), the streamed tables written once.
DEM partition in YADE (yade_partition): the stored run of this scene through YADE (coupling.dem_partition = "yade",
on the YADE_CELL = 10 mm grid: the production grid through YADE was extrapolated to ~70 min on the loaded machine)
against the resolution study's native run on the same grid: held-phase interface force (1 %, deterministic), final
centroids (5 % of the wall height, the cross-code goal), the divergence in time, the exchange cost per coupling step;
block histories and interface force of both on one plot. --live with YADE installed reruns it. The partition
blocks the out-of-plane rotations of planar clumps (adapters/yade/partition_server.py): the run stored before
that (rotations free) tilted the loaded sliding block1 about x from round-off until it lay on its side (centroid
y 12.5 -> 2.5 mm from 0.48 s, final centroids 81 mm apart); now 1.1 mm apart at t_end.
Interface transfer (issue 15): the scene sets mpm.boundary_sliver_fraction = 0.1 (coupler/mpm/kernels.py
_sliver_weight): a support node of a boundary particle holding less than 10 % of a full node's mass (rho h^2) takes
a share of the point load and of the velocity read scaled by its mass (mass-weighted, Peskin 2002), full nodes keep
the plain shape weights. Without it (the default, 0) a boundary point of the staircase is flung off the grid 30-50
ms after the release (measured: h = 10 mm stops at t = 0.148 s, boundary particle 38 at x = -0.079 m): a node holding
a sliver of mass got a = N_i f / m_i and the boundary particle read its velocity. Measured at h = 10 mm, fractions
0.02, 0.05, 0.1, 0.25 all run to 0.8 s; the project default stays 0 because no fraction tried keeps the guard
cases (coupled_free_collision energy closure, coupled_resting_load settlement) passing (README).
"""
from __future__ import annotations

import math
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from coupler.errors import SimulationError
from coupler.results import Result
from coupler.scene import load_scene
from validation.cases.coupled_common.balance import interface_balance, plot_interface, read_log
from validation.metrics import rotation_z_deg, surface_profile

TITLE = "Coupled retaining wall (Bui 2014): MPM backfill behind six DEM blocks, held then released"
FULL_ONLY = False
BLOCKS = [f"block{k}" for k in range(1, 7)]
BLOCK_W, BLOCK_H, WALL_H = 0.032, 0.025, 0.15
PRODUCTION_CELL = 0.0025
RESOLUTION = (0.01, 0.005, 0.0025)               # default mode
RESOLUTION_FULL = (0.01, 0.005, 0.0025, 0.00125)  # --full
# per-grid overrides of the --full resolution runs: at h = 1.25 mm the coupling step (= the MPM step, cfl h / c) is
# halved. Before kernels._support_norm a boundary particle on a support of sliver nodes carried its load on ~1 % of
# a node's mass and the interface diverged (cfl 0.5: out of the grid at t = 0.5057 s; cfl 0.25 reached t_end, but
# h = 2.5 mm with cfl 0.25 diverged at 0.7944 s). With it such loads were counted as dropped (h = 1.25 mm stopped on
# the 1 % dropped-load limit at 0.376 s cfl 0.5 / 0.6725 s cfl 0.25); now the part a sliver support cannot carry goes
# to the nearest full nodes (kernels._transfer): h = 1.25 mm cfl 0.25 reaches t_end, nothing dropped (18,851 rerouted
# applications, 1.3e-4 of the load impulse), 2.5 vs 1.25 mm final centroids 6.8 mm = 4.6 % (README, issue 15)
FULL_EXTRA = {0.00125: {"mpm.cfl": 0.25}}
ENSEMBLE_CELL = 0.01                              # default mode; --full: PRODUCTION_CELL
N_ENSEMBLE = 8
ENSEMBLE_REL = 1e-3
STABLE_TOL = 0.05
YADE_HELD_RTOL = 0.01         # held-phase interface force, YADE vs native DEM partition (yade_partition)
ROT_BOTTOM_MAX = 5.0          # deg
SLIDE_MIN = 0.010             # m
SEPARATION_MIN = 0.005        # m
SNAP_TIMES = (0.0, 0.1, 0.2, 0.3, 0.45, 0.8)
QUICK = None                  # tests: dict of scene overrides (short run), set by the test


def _scene(ctx, cell, extra=None, name=None, vtk=False):
    """The case scene on a grid of cell size `cell`; the ParaView series only where asked (the production run)."""
    ov = {"mpm.grid.cell_size": cell, "output.vtk": vtk}
    if QUICK:
        ov.update(QUICK)
    if extra:
        ov.update(extra)
    return load_scene(ctx.case_dir / "scene.toml", overrides=ov, name=name)


# The stored YADE-partition run (reference_runs/coupled_retaining_wall/yade_partition/yade): on the YADE_CELL grid,
# not the production one: the production run through YADE was extrapolated from its first 0.05 s (5.0 min wall on
# the loaded machine, load 10 on 2 cores) to ~70 min, over the ~25 min budget of a stored run (issue 15)
YADE_CELL = 0.01
YADE_DIR = "yade_partition"     # reference_runs/coupled_retaining_wall/yade_partition/yade


def yade_scene(case_dir, partition="yade"):
    """The case scene on the YADE_CELL grid with the DEM partition `partition` (coupling.dem_partition), no ParaView
    series, MPM snapshots at the first and last output time only: the scene the stored run in
    reference_runs/coupled_retaining_wall/yade_partition/yade was made from (its provenance.json scene_hash is this
    scene's text_hash); with partition = "native" the run it is compared with."""
    return load_scene(case_dir / "scene.toml", overrides={
        "mpm.grid.cell_size": YADE_CELL, "output.vtk": False, "output.particles_interval": 0.8,
        "coupling.dem_partition": partition}, name=f"{partition}_partition")


def t_release(scene) -> float:
    """When the blocks are released: their [[dem.clusters]] motion `until` (0 without a motion)."""
    mo = scene.dem.clusters[0].motion
    return 0.0 if mo is None else float(mo.until)


def block_histories(res, shift: float = 0.0):
    """t - shift, x, y, rotation about z [deg] per block (shift: the release time, to plot the DEM-only wall on the
    time axis of the coupled one)."""
    out = {}
    for name in BLOCKS:
        b = res.body(name)
        out[name] = (b["t"].to_numpy() - shift, b["x"].to_numpy(), b["y"].to_numpy(), rotation_z_deg(b))
    return out


def final_row(hist) -> dict:
    row = {}
    for name in BLOCKS:
        _, x, y, a = hist[name]
        row[f"x_final_{name}"], row[f"y_final_{name}"], row[f"rot_final_{name}"] = x[-1], y[-1], a[-1]
    return row


def failure_metrics(hist, t_rel: float) -> dict:
    """The failure-mode numbers of one run (after the release): dx, dy final, max |rotation|, joint separations."""
    m = {}
    for name in BLOCKS:
        t, x, y, a = hist[name]
        after = t >= t_rel - 1e-12
        m[name] = {"dx": float(x[-1] - x[0]), "dy": float(y[-1] - y[0]),
                   "rot_max": float(np.abs(a[after]).max()), "rot_final": float(a[-1]),
                   "lift_max": float(np.abs(y[after] - y[0]).max())}
    sep = []
    for lo, hi in zip(BLOCKS[:-1], BLOCKS[1:]):
        d0 = np.array([hist[hi][1][0] - hist[lo][1][0], hist[hi][2][0] - hist[lo][2][0]])
        d1 = np.array([hist[hi][1][-1] - hist[lo][1][-1], hist[hi][2][-1] - hist[lo][2][-1]])
        sep.append(float(np.hypot(*(d1 - d0))))
    m["separation"] = sep
    return m


def check_failure_mode(ctx, m, wall, label=""):
    p = f"{label}: " if label else ""
    for name in BLOCKS:
        ctx.check_max(f"{p}{name} moves rightwards [-dx, m]", -m[name]["dx"], 0.0, wall_time_s=wall,
                      note=f"dx = {1e3 * m[name]['dx']:.1f} mm, dy = {1e3 * m[name]['dy']:.1f} mm, final rotation "
                           f"{m[name]['rot_final']:.1f} deg")
    ctx.check_max(f"{p}wall collapses: top block vertical displacement [dy6, m]", m["block6"]["dy"], -BLOCK_H,
                  wall_time_s=wall,
                  note=f"top block falls {-1e3 * m['block6']['dy']:.1f} mm (must be >= one block height, 25 mm)")
    b1 = m["block1"]
    ctx.check_max(f"{p}bottom block slides [-dx1, m]", -b1["dx"], -SLIDE_MIN, wall_time_s=wall,
                  note=f"slide {1e3 * b1['dx']:.1f} mm (must be >= {1e3 * SLIDE_MIN:g} mm)")
    ctx.check_max(f"{p}bottom block max |rotation| [deg]", b1["rot_max"], ROT_BOTTOM_MAX, wall_time_s=wall,
                  note=f"the experiment's bottom block slides without rotating; max lift {1e3 * b1['lift_max']:.2f} mm")
    for name in BLOCKS[1:]:
        ctx.check_max(f"{p}{name} translates [-dx, m]", -m[name]["dx"], -SLIDE_MIN, wall_time_s=wall,
                      note=f"dx = {1e3 * m[name]['dx']:.1f} mm")
        ctx.check_max(f"{p}{name} rotates [-max |rotation|, deg]", -m[name]["rot_max"], -ROT_BOTTOM_MAX,
                      wall_time_s=wall, note=f"max |rotation| {m[name]['rot_max']:.1f} deg (must be >= "
                                             f"{ROT_BOTTOM_MAX:g})")
    sep = m["separation"]
    ctx.check_max(f"{p}blocks separate: smallest joint opening [-min, m]", -min(sep), -SEPARATION_MIN,
                  wall_time_s=wall, note="relative displacement of each block to the one below, joints 1-2 .. 5-6: "
                                         + ", ".join(f"{1e3 * s:.1f}" for s in sep) + " mm")


def block_outline(x, y, ang_deg):
    c, s = math.cos(math.radians(ang_deg)), math.sin(math.radians(ang_deg))
    hw, hh = BLOCK_W / 2, BLOCK_H / 2
    pts = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh], [-hw, -hh]])
    return x + c * pts[:, 0] - s * pts[:, 1], y + s * pts[:, 0] + c * pts[:, 1]


def final_surface(frame, cell, ppc, width):
    d = cell / ppc
    nb = int(math.ceil(width / cell))
    return surface_profile(frame["x"].to_numpy(), frame["y"].to_numpy() + d / 2, cell, nb)


GOAL_S = 60.0                 # issue 15: the production run in under 60 s on this 2-core machine


def perf_note(res, wall, load=None) -> str:
    """The production run's wall time against GOAL_S and its split: solvers (build, MPM, DEM, the coupling's own
    work), output at the output times (summary cost_s.output: tables, snapshots, their CSV writes), the writes after
    the run (Result.write + the ParaView series: the case's wall time minus the run's) and the rest of the loop;
    the process CPU time (all threads) and the load average at the end, since the machine is shared."""
    c = res.summary["coupling"]
    cs = c["cost_s"]
    own = cs.get("map", 0.0) + cs.get("interface", 0.0) + cs.get("exchange", 0.0)
    solvers = cs["build"] + cs["mpm"] + cs["dem"] + own
    out_run = cs.get("output", float("nan"))
    run_wall = float(res.summary["wall_time_s"])
    after = wall - run_wall
    verdict = "meets" if wall <= GOAL_S else "misses"
    return (f"production run (h = {1e3 * PRODUCTION_CELL:g} mm): wall time {wall:.1f} s ({verdict} the {GOAL_S:g} s goal"
            f"{'' if load is None else f' at load average {load:.1f} on 2 cores'}): solvers {solvers:.1f} s (build "
            f"{cs['build']:.1f}, MPM {cs['mpm']:.1f}, DEM {cs['dem']:.1f}, coupling own {own:.1f} = map "
            f"{cs.get('map', 0):.2f} + interface {cs.get('interface', 0):.2f} + exchange {cs.get('exchange', 0):.2f}), "
            f"output at the output times {out_run:.1f} s, writes after the run (tables, ParaView) {after:.1f} s, rest "
            f"of the loop {run_wall - solvers - out_run:.1f} s; process CPU time {c.get('cpu_time_s', float('nan')):.1f}"
            f" s (2 numba threads); {res.summary['steps']} coupling steps of {c['coupling_dt']:.4g} s = MPM step, DEM "
            f"step {c['coupling_dt'] / c['dem_substeps']:.4g} s, sub-step ratio {c['dem_substeps']}; "
            f"{res.summary['particles']} particles (DEM spheres + MPM points)")


def coupling_step(scene) -> float:
    """The coupling step the scene runs with (coupler/coupling/solver.coupling_step, as CoupledRun): the MPM CFL
    step, or the interface contact's stable step when that is smaller, as at h = 10 and 5 mm here."""
    from coupler.coupling.partitions import MPMPartition
    from coupler.coupling.solver import coupling_step as step_of
    return step_of(scene, MPMPartition(scene, None).dt)[0]


def run_ensemble(ctx, cell, tag):
    """N coupled runs with the coupling step perturbed by (1 - k rel) through coupling.dt (member 0: the scene
    unchanged); rows of final block states. (Perturbing mpm.cfl instead left the step unchanged wherever the interface
    contact limit sets it: at h = 10 mm the 8 members were bitwise the same run.)"""
    base = _scene(ctx, cell)
    dt0 = coupling_step(base)
    rows, hists = [], []
    members = ctx.run_many([(base if k == 0 else _scene(ctx, cell, {"coupling.dt": dt0 * (1.0 - ENSEMBLE_REL * k)}),
                             f"{tag}_{k}") for k in range(N_ENSEMBLE)], side_by_side=True)  # or dask tasks
    for k, res in enumerate(members):
        h = block_histories(res)
        hists.append(h)
        rows.append({"run": k, "dt": res.summary["dt"], "wall_time_s": ctx.wall_times[f"{tag}_{k}"],
                     **final_row(h)})
    return pd.DataFrame(rows), hists


def _run_or_stopped(ctx, scene, tag):
    """ctx.run; a run that stops (SimulationError: blow-up, dropped loads) is a failing row naming the error, and its
    tables up to the last output time (written as it went) are read back."""
    t0 = time.perf_counter()
    try:
        return ctx.run(scene, tag=tag)
    except SimulationError as e:
        ctx.wall_times[tag] = time.perf_counter() - t0
        r = Result.read(ctx.out_dir / tag)
        t_last = float(r.bodies["t"].max())
        ctx.check_max(f"{tag}: run stops before t_end [stops]", 1.0, 0.0, wall_time_s=ctx.wall_times[tag],
                      note=f"stopped: {e}; tables read back to t = {t_last:.4g} s")
        return r


def dem_only_ensemble(ctx, n):
    """The DEM-only native wall of xval_retaining_wall (its wall.toml, settle-then-release), N time-step
    perturbations; None when the scene or validation/ensembles.py is missing (reason in the notes)."""
    from validation.framework import CASES_DIR
    path = CASES_DIR / "xval_retaining_wall" / "wall.toml"
    text = path.read_text()
    try:
        from validation.ensembles import seeds_or_perturbations
    except ImportError as e:
        ctx.notes.append(f"DEM-only ensemble not run: validation/ensembles.py missing ({e})")
        return None, None
    from coupler.scene import loads_scene
    rows, hists = [], []
    scenes = [loads_scene(txt, name=f"dem_only_{k}", base_dir=path.parent)
              for k, txt in enumerate(seeds_or_perturbations(text, n, kind="dt", rel=ENSEMBLE_REL))]
    members = ctx.run_many([(sc, f"dem_only_{k}") for k, sc in enumerate(scenes)], side_by_side=True)
    for k, (sc, res) in enumerate(zip(scenes, members)):
        h = block_histories(res, t_release(sc))
        hists.append(h)
        rows.append({"run": k, "wall_time_s": ctx.wall_times[f"dem_only_{k}"], **final_row(h)})
    return pd.DataFrame(rows), hists


def evaluate(ctx):
    # -- production run -------------------------------------------------------------------------------------
    scene = _scene(ctx, PRODUCTION_CELL, vtk=True)
    t_rel = t_release(scene)
    res = ctx.run(scene, tag="coupled")
    wall = ctx.wall_times["coupled"]
    hist = block_histories(res)
    m = failure_metrics(hist, t_rel)
    check_failure_mode(ctx, m, wall)
    interface_balance(ctx, res, "coupled", wall)
    import os
    ctx.notes.append(perf_note(res, wall, os.getloadavg()[0]))
    log = read_log(ctx, "coupled")
    k_rel = log.iloc[(log["t"] - t_rel).abs().argmin()]
    ctx.notes.append(f"at the release (t = {t_rel:g} s): backfill kinetic energy {k_rel['K_mpm']:.3g} J vs its "
                     f"elastic energy {k_rel['E_mpm']:.3g} J (x thickness); end of run: MPM K {log['K_mpm'].iloc[-1]:.3g} J, "
                     f"DEM K {log['K_dem'].iloc[-1]:.3g} J")
    c = res.summary["coupling"]
    st = c.get("mpm_stranded_boundary_particles", {})
    ctx.notes.append(f"interface transfer: mpm.boundary_sliver_fraction = {scene.mpm.boundary_sliver_fraction:g} "
                     f"(support nodes below that fraction of a full node's mass take a mass-weighted share); "
                     f"{c.get('mpm_points')} MPM points, {c.get('mpm_boundary_particles')} boundary particles "
                     f"({len(scene.coupling.geometry.index)} on the interface); stranded boundary particles "
                     f"{st.get('particle_steps', 'n/a')} particle-steps (most at once {st.get('max_at_once', 'n/a')})")
    d = c.get("mpm_dropped_loads", {})
    if d:
        ctx.notes.append(f"dropped interface loads: {d}")

    # -- resolution study -----------------------------------------------------------------------------------
    cells = RESOLUTION_FULL if ctx.full else RESOLUTION
    finals, walls = {}, {}
    other = [h for h in cells if abs(h - PRODUCTION_CELL) >= 1e-12]
    if ctx.full:       # one by one: a run that stops is read back to its last output time and reported
        more = {h: _run_or_stopped(ctx, _scene(ctx, h, FULL_EXTRA.get(h)), f"h{1e3 * h:g}mm") for h in other}
        for h, ov in FULL_EXTRA.items():
            ctx.notes.append(f"resolution: h = {1e3 * h:g} mm runs with {ov} (the coupling step halved: with the CFL "
                             f"step 0.5 h/c a material point leaves the grid at t = 0.507 s, measured 2026-12-02 on "
                             f"the code that reroutes sliver loads to the nearest full nodes, kernels._transfer; README)")
    else:
        more = dict(zip(other, ctx.run_many([(_scene(ctx, h), f"h{1e3 * h:g}mm") for h in other])))
    hists = {h: block_histories(res if abs(h - PRODUCTION_CELL) < 1e-12 else more[h]) for h in cells}
    # compared at the last output time every grid reached (t_end unless a run stopped)
    t_cmp = min(float(hh[BLOCKS[0]][0][-1]) for hh in hists.values())
    for h in cells:
        if abs(h - PRODUCTION_CELL) < 1e-12:
            r, w = res, wall
        else:
            r, w = more[h], ctx.wall_times[f"h{1e3 * h:g}mm"]
        hh = hists[h]
        j = int(np.argmin(np.abs(hh[BLOCKS[0]][0] - t_cmp)))
        finals[h] = (np.array([[hh[n][1][j], hh[n][2][j], hh[n][3][j]] for n in BLOCKS]), hh, r)
        walls[h] = w
    if t_cmp < scene.time.t_end - 0.5 * scene.time.output_interval:
        ctx.notes.append(f"resolution: a run stopped, the grids are compared at t = {t_cmp:.3g} s (not t_end)")
    hs = sorted(cells)
    fin = finals[hs[0]][0]
    err = {h: float(np.hypot(*(finals[h][0][:, :2] - fin[:, :2]).T).max()) for h in hs}
    # -- the DEM partition in YADE (stored run on the YADE_CELL grid) against the native partition ----------------
    native_y = None
    if any(abs(h - YADE_CELL) < 1e-12 for h in cells) and t_cmp >= scene.time.t_end - 0.5 * scene.time.output_interval:
        native_y = finals[[h for h in cells if abs(h - YADE_CELL) < 1e-12][0]][2]
    yade_partition(ctx, native_y, walls.get(YADE_CELL, float("nan")), t_rel)
    # -- ensemble ---------------------------------------------------------------------------------------------
    ecell = PRODUCTION_CELL if ctx.full else ENSEMBLE_CELL
    ens, ens_hists = run_ensemble(ctx, ecell, "ens")
    ens.to_csv(ctx.out_dir / "ensemble_coupled.csv", index=False)
    spread = max(float(np.hypot(ens[f"x_final_{n}"].std(), ens[f"y_final_{n}"].std())) for n in BLOCKS)
    d2 = err[hs[1]]
    ctx.check_max("resolution: final centroids, two finest grids, max distance / wall height", d2 / WALL_H,
                  STABLE_TOL, wall_time_s=walls[hs[0]],
                  note=f"h = {1e3 * hs[1]:g} vs {1e3 * hs[0]:g} mm: {1e3 * d2:.1f} mm; coupled ensemble spread "
                       f"(max over blocks of the std of the final centroid, h = {1e3 * ecell:g} mm, N = "
                       f"{N_ENSEMBLE}) {1e3 * spread:.1f} mm = {100 * spread / WALL_H:.1f} % of the wall height")
    ctx.notes.append("resolution (h [mm]: wall time [s], max final-centroid distance to the finest [mm], bottom-block "
                     "max |rotation| [deg]): " + "; ".join(
                         f"{1e3 * h:g}: {walls[h]:.1f} s, {1e3 * err[h]:.1f} mm, "
                         f"{failure_metrics(finals[h][1], t_rel)['block1']['rot_max']:.1f} deg" for h in hs))
    for h in hs:
        if h != PRODUCTION_CELL:
            mh = failure_metrics(finals[h][1], t_rel)
            ctx.notes.append(f"h = {1e3 * h:g} mm: bottom-block slide {1e3 * mh['block1']['dx']:.1f} mm, max |rot| "
                             f"{mh['block1']['rot_max']:.1f} deg; top-block drop {-1e3 * mh['block6']['dy']:.1f} mm; "
                             f"smallest joint opening {1e3 * min(mh['separation']):.1f} mm")
    em = [failure_metrics(hh, t_rel) for hh in ens_hists]
    ctx.notes.append(f"coupled ensemble (h = {1e3 * ecell:g} mm, N = {N_ENSEMBLE}, coupling dt x (1 - k "
                     f"{ENSEMBLE_REL:g})): bottom-block max |rot| {min(e['block1']['rot_max'] for e in em):.1f} .. "
                     f"{max(e['block1']['rot_max'] for e in em):.1f} deg, slide "
                     f"{1e3 * min(e['block1']['dx'] for e in em):.1f} .. {1e3 * max(e['block1']['dx'] for e in em):.1f}"
                     f" mm; final x [mm] mean +- std per block: " + ", ".join(
                         f"{1e3 * ens[f'x_final_{n}'].mean():.1f} +- {1e3 * ens[f'x_final_{n}'].std():.1f}"
                         for n in BLOCKS))
    n_bottom_ok = sum(e["block1"]["rot_max"] < ROT_BOTTOM_MAX for e in em)
    ctx.check_max("ensemble: runs whose bottom block rotates >= 5 deg [-]", float(N_ENSEMBLE - n_bottom_ok), 0.0,
                  wall_time_s=float(ens["wall_time_s"].sum()), note=f"{n_bottom_ok} of {N_ENSEMBLE} below 5 deg")
    dem, dem_hists = None, None
    if ctx.full:
        dem, dem_hists = dem_only_ensemble(ctx, N_ENSEMBLE)
    else:
        ctx.notes.append("DEM-only wall (xval_retaining_wall wall.toml, settle-then-release, ~70 s a run): its "
                         f"ensemble of {N_ENSEMBLE} and the comparison with the coupled ensemble run with --full only")
    if dem_hists:      # on the coupled time axis: released at t_rel
        dem_hists = [{n: (h[n][0] + t_rel,) + h[n][1:] for n in BLOCKS} for h in dem_hists]
    if dem is not None and len(dem) == 1:
        ctx.notes.append("DEM-only wall (xval_retaining_wall wall.toml, one native run; its ensemble with --full): "
                         "final x [mm] per block, DEM-only vs coupled ensemble mean (difference in coupled stds): "
                         + ", ".join(f"{1e3 * dem[f'x_final_{n}'].iloc[0]:.1f} vs {1e3 * ens[f'x_final_{n}'].mean():.1f}"
                                     f" ({(dem[f'x_final_{n}'].iloc[0] - ens[f'x_final_{n}'].mean()) / max(ens[f'x_final_{n}'].std(), 1e-12):+.1f})"
                                     for n in BLOCKS)
                         + "; final rotation [deg]: " + ", ".join(
                             f"{dem[f'rot_final_{n}'].iloc[0]:.0f} vs {ens[f'rot_final_{n}'].mean():.0f}" for n in BLOCKS))
    if dem is not None and len(dem) > 1:
        dem.to_csv(ctx.out_dir / "ensemble_dem_only.csv", index=False)
        from validation.ensembles import compare_ensembles
        cols = [c for c in ens.columns if c.startswith(("x_final", "y_final", "rot_final"))]
        for r in compare_ensembles(ens, dem, cols):
            ctx.check_max(f"coupled vs DEM-only ensemble: {r['column']} z", r["z"], 2.0, backend="native_dem",
                          note=f"coupled {r['mean_a']:.4g} +- {r['std_a']:.2g} (n {r['n_a']}), DEM-only "
                               f"{r['mean_b']:.4g} +- {r['std_b']:.2g} (n {r['n_b']}); informative: the models differ")

    # -- plots ------------------------------------------------------------------------------------------------
    _plot_histories(ctx, hist, ens_hists, dem_hists, t_rel)
    _plot_snapshots(ctx, res, scene, hist)
    _plot_surface_interface(ctx, res, scene, log, finals, walls, err, hs)


def stored_yade_run(ctx):
    """The YADE-partition run: live with --live when YADE is installed, else the stored one if it was made from
    this scene (provenance scene_hash); (result, wall time [s], why-not)."""
    import json
    import shutil
    from validation.references import stored_dir
    sc = yade_scene(ctx.case_dir)
    if ctx.live and shutil.which("yade"):
        res = ctx.run(sc, tag="yade_partition")
        return res, ctx.wall_times["yade_partition"], ""
    d = stored_dir(ctx.name, YADE_DIR, "yade")
    if not (d / "provenance.json").exists():
        return None, float("nan"), f"no stored run in {d}"
    prov = json.loads((d / "provenance.json").read_text())
    if prov.get("scene_hash") != sc.text_hash:
        return None, float("nan"), (f"the stored run in {d.name} was made for another version of the scene (hash "
                                    f"mismatch): rerun it (README, coupled retaining wall)")
    return Result.read(d), float(prov.get("wall_time_s", float("nan"))), ""


def yade_partition(ctx, native, native_wall, t_rel):
    """The coupled wall with the DEM partition in YADE beside the native partition, same native MPM, YADE_CELL grid
    (the native run: the resolution study's run on that grid, the same scene but for the output). Rows:
      * held phase (blocks fixed, t <= t_release): the interface force the MPM receives, mean over the held phase,
        relative difference <= YADE_HELD_RTOL = 1 % (deterministic: the backfill settling against held blocks; the
        two DEM codes compute the same wall contacts, measured 320.4678 vs 320.4677 N/m on coupled_resting_load);
      * after the release (chaotic collapse): per block the final centroid distance, max over the blocks / wall
        height <= STABLE_TOL = 5 % (the cross-code goal of xval_retaining_wall, the same tolerance as the resolution
        row); the coupled ensemble's spread at h = 10 mm (~0.1 mm) is far below it, so this row is a looser bound
        than the run-to-run noise of one code: the basis is the cross-code goal, not the spread.
    Plus the exchange cost per coupling step (summary coupling.yade_cost_per_step_us) as a note."""
    res, wall, why = stored_yade_run(ctx)
    if res is None or native is None:
        ctx.fail("YADE partition vs native: final centroids", why or "no native run on the YADE_CELL grid to t_end",
                 backend="yade_partition")
        return
    hy, hn = block_histories(res), block_histories(native)
    it_y, it_n = res.interface, native.interface
    held = lambda it: it[(it["t"] > 0.5 * t_rel) & (it["t"] <= t_rel)]     # the settled half of the held phase
    for comp in ("fx_mpm", "fy_mpm"):
        fy_, fn_ = float(held(it_y)[comp].mean()), float(held(it_n)[comp].mean())
        ctx.check_max(f"YADE partition vs native: held-phase interface force {comp} [rel]", abs(fy_ - fn_) /
                      max(abs(fn_), 1e-300), YADE_HELD_RTOL, backend="yade_partition", wall_time_s=wall,
                      note=f"mean over ({0.5 * t_rel:g}, {t_rel:g}] s: YADE {fy_:.5g} N, native {fn_:.5g} N")
    d = {n: float(np.hypot(hy[n][1][-1] - hn[n][1][-1], hy[n][2][-1] - hn[n][2][-1])) for n in BLOCKS}
    worst = max(d, key=d.get)
    ctx.check_max("YADE partition vs native: final centroids, max distance / wall height", d[worst] / WALL_H,
                  STABLE_TOL, backend="yade_partition", wall_time_s=wall,
                  note=f"h = {1e3 * YADE_CELL:g} mm; per block [mm]: " + ", ".join(f"{1e3 * d[n]:.1f}" for n in BLOCKS)
                       + "; final rotation YADE / native [deg]: " + ", ".join(
                           f"{hy[n][3][-1]:.0f} / {hn[n][3][-1]:.0f}" for n in BLOCKS))
    t_ = hn[BLOCKS[0]][0]
    dist = np.array([max(float(np.hypot(hy[n][1][j] - hn[n][1][j], hy[n][2][j] - hn[n][2][j])) for n in BLOCKS)
                     for j in range(min(len(t_), len(hy[BLOCKS[0]][0])))])
    apart = np.nonzero(dist > 1e-3)[0]
    ctx.notes.append(
        "YADE vs native partition, max centroid distance over the blocks [mm] at t = 0.2 / 0.3 / 0.4 / 0.5 / 0.6 / "
        "0.8 s: " + " / ".join(f"{1e3 * dist[int(np.argmin(np.abs(t_[:len(dist)] - tt)))]:.1f}"
                               for tt in (0.2, 0.3, 0.4, 0.5, 0.6, 0.8))
        + (f"; first above 1 mm at t = {t_[apart[0]]:.2f} s" if len(apart) else "")
        + f"; lowest bottom-block centroid y: YADE {1e3 * hy[BLOCKS[0]][2].min():.1f} mm, native "
          f"{1e3 * hn[BLOCKS[0]][2].min():.1f} mm (resting on the floor: {1e3 * hn[BLOCKS[0]][2][0]:.1f} mm; lower, its "
          f"bottom row of spheres is inside the floor y = 0)")
    c = res.summary.get("coupling", {})
    yc = c.get("yade_cost_per_step_us", {})
    nc = native.summary.get("coupling", {}).get("cost_per_step_us", {})
    ctx.notes.append(
        f"YADE partition (h = {1e3 * YADE_CELL:g} mm, {res.summary.get('steps')} coupling steps, "
        f"{c.get('dem_substeps')} DEM steps each; wall {wall:.0f} s vs native {native_wall:.0f} s): per coupling step "
        f"[ms] DEM side {1e-3 * c.get('cost_per_step_us', {}).get('dem', float('nan')):.2f} (native "
        f"{1e-3 * nc.get('dem', float('nan')):.2f}), of which exchange CPU {1e-3 * yc.get('exchange_cpu', float('nan')):.2f}"
        f" (coupler {1e-3 * yc.get('exchange_cpu_coupler', float('nan')):.2f} + YADE "
        f"{1e-3 * yc.get('exchange_cpu_yade', float('nan')):.2f}), exchange wall "
        f"{1e-3 * yc.get('exchange_wall', float('nan')):.2f}, YADE O.run CPU {1e-3 * yc.get('yade_run_cpu', float('nan')):.2f}"
        f", facet move CPU {1e-3 * yc.get('yade_move_facets_cpu', float('nan')):.2f}; YADE start-up "
        f"{c.get('yade_startup_s', float('nan')):.1f} s")
    fig, axs = plt.subplots(1, 3, figsize=(17, 4.5))
    for k, n in enumerate(BLOCKS):
        for h_, ls, lab in ((hn, "-", "native"), (hy, "--", "YADE")):
            t, x, y, a = h_[n]
            axs[0].plot(t, x, ls, color=f"C{k}", lw=1.2, label=f"{n} {lab}" if k in (0, 5) else None)
            axs[1].plot(t, a, ls, color=f"C{k}", lw=1.2)
    for it, ls, lab in ((it_n, "-", "native"), (it_y, "--", "YADE")):
        axs[2].plot(it["t"], it["fx_mpm"], ls, color="C0", lw=0.8, label=f"fx, {lab}")
        axs[2].plot(it["t"], it["fy_mpm"], ls, color="C3", lw=0.8, label=f"fy, {lab}")
    for ax in axs[:2]:
        ax.axvline(t_rel, color="k", ls=":", lw=0.8)
    axs[0].set(xlabel="t [s]", ylabel="block centroid x [m]",
               title=f"DEM partition native (solid) vs YADE (dashed), h = {1e3 * YADE_CELL:g} mm")
    axs[1].set(xlabel="t [s]", ylabel="rotation about z [deg]")
    axs[2].set(xlabel="t [s]", ylabel="interface force on the MPM x thickness [N]", title="per coupling step")
    axs[0].legend(fontsize=7)
    axs[2].legend(fontsize=7)
    ctx.save_plot(fig, f"{ctx.name}_yade_partition")


def _plot_histories(ctx, hist, ens_hists, dem_hists, t_rel):
    fig, axs = plt.subplots(1, 3, figsize=(16, 4.5))
    for k, name in enumerate(BLOCKS):
        t, x, y, a = hist[name]
        axs[0].plot(t, x, color=f"C{k}", lw=1.6, label=f"{name} coupled" if k in (0, 5) else None)
        axs[1].plot(t, a, color=f"C{k}", lw=1.6)
        axs[2].plot(x, y, color=f"C{k}", lw=1.6)
        for hs_, style in ((ens_hists, "-"), (dem_hists or [], "--")):
            for j, hh in enumerate(hs_):
                tt, xx, yy, aa = hh[name]
                lab = None
                if k == 0 and j == 0:
                    lab = "coupled ensemble (coarse grid)" if style == "-" else "DEM-only (native)"
                axs[0].plot(tt, xx, style, color=f"C{k}", lw=0.4, alpha=0.5, label=lab)
                axs[1].plot(tt, aa, style, color=f"C{k}", lw=0.4, alpha=0.5)
                axs[2].plot(xx, yy, style, color=f"C{k}", lw=0.4, alpha=0.5)
    for ax in axs[:2]:
        ax.axvline(t_rel, color="k", ls=":", lw=0.8)
    axs[0].set(xlabel="t [s]", ylabel="block centroid x [m]", title="colour = block 1 (bottom) ... 6; dotted: release")
    axs[1].set(xlabel="t [s]", ylabel="rotation about z [deg]")
    axs[2].set(xlabel="x [m]", ylabel="y [m]", title="centroid paths", aspect="equal")
    axs[0].legend(fontsize=7)
    ctx.save_plot(fig, f"{ctx.name}_blocks")


def _plot_snapshots(ctx, res, scene, hist):
    times = [s[0] for s in res.particles]
    want = [t for t in SNAP_TIMES if t <= times[-1] + 1e-9] or [times[-1]]
    fig, axs = plt.subplots(len(want), 1, figsize=(9, 2.0 * len(want)), squeeze=False)
    for ax, tw in zip(axs[:, 0], want):
        i = int(np.argmin(np.abs(np.array(times) - tw)))
        t, fr = res.particles[i]
        ax.scatter(fr["x"], fr["y"], s=0.3, c=fr["eps_p"], cmap="viridis", vmin=0, vmax=0.5, rasterized=True)
        for k, name in enumerate(BLOCKS):
            tt, x, y, a = hist[name]
            j = int(np.argmin(np.abs(tt - t)))
            ax.fill(*block_outline(x[j], y[j], a[j]), color=f"C{k}", alpha=0.7)
        ax.set(xlim=(0, 0.6), ylim=(0, 0.17), aspect="equal", title=f"t = {t:.2f} s (colour: eps_p 0 .. 0.5)")
    fig.tight_layout()
    ctx.save_plot(fig, f"{ctx.name}_snapshots")


def _plot_surface_interface(ctx, res, scene, log, finals, walls, err, hs):
    body = scene.mpm.bodies[0]
    fig, axs = plt.subplots(1, 4, figsize=(20, 4.2))
    for h in hs:
        r = finals[h][2]
        xs, s = final_surface(r.particles[-1][1], h, body.particles_per_cell, 0.6)
        axs[0].plot(xs, s, lw=1, label=f"h = {1e3 * h:g} mm")
    axs[0].set(xlabel="x [m]", ylabel="backfill surface [m]", title=f"final backfill surface, t = "
               f"{res.particles[-1][0]:.2f} s", aspect="equal", xlim=(0, 0.6))
    axs[0].legend(fontsize=7)
    plot_interface(axs[1], axs[2], res, log)
    axs[3].plot([walls[h] for h in hs], [1e3 * err[h] for h in hs], "o-")
    for h in hs:
        axs[3].annotate(f"{1e3 * h:g} mm", (walls[h], 1e3 * err[h]), fontsize=8)
    axs[3].set(xlabel="wall time [s]", ylabel="max final-centroid change vs finest [mm]", title="speed against error")
    fig.tight_layout()
    ctx.save_plot(fig)
