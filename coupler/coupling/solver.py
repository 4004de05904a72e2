"""run_coupled(scene, out_dir, progress) -> Result: the partitioned MPM-DEM run.

Tables (coupler/results.py):
  bodies.csv     DEM bodies (free spheres and clusters), as a DEM-only run
  contacts.csv   DEM contacts, the interface wall appearing as j = "wall:interface"
  mpm_bodies.csv the MPM bodies (t, body, mass, centroid, velocity, kinetic energy, displacements, extent, ...,
                 per unit depth), one row per MPM body per output time, as an MPM-only run
  energy.csv     both partitions in J: DEM (3D, J) + MPM (per unit depth) x thickness, column by column;
                 dissipated = DEM contact dissipation only (the MPM's plastic work and its numerical dissipation
                 are not integrated; they show as the residual of the balance). Per partition: coupling_log.csv.
  interface.csv  t, fx_dem, fy_dem, fx_mpm, fy_mpm, work_dem, work_mpm, one row per coupling step: the
                 time-averaged force the DEM spheres put on the wall [N], the force the MPM receives x thickness
                 [N], and the cumulative work of each side on the interface [J]
  particles_<n>.csv   MPM snapshots at the output times (every output.particles_interval)
  interface_points.csv  per interface particle (outline order): x0, y0, ux, uy at the end, fx, fy the mean point
                 load [N per unit depth] over the last output interval
  coupling_log.csv  t, px/py of each partition [N s] (MPM x thickness), K/P/E of each partition [J], D_dem
  summary.json   + coupling: scheme, mapper, steps, substeps, thickness, the cost split per coupling step, and
                 mpm_dropped_loads (MPMSolver.dropped_loads: count, impulse_dropped, impulse_applied, max_fraction,
                 limit) + dropped_load_steps (coupling steps in which fx_mpm/fy_mpm were reduced by dropped load)
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from coupler.coupling.mappers import make_mapper
from coupler.coupling.partitions import MPMPartition, dem_partition_class
from coupler.coupling.schemes import make_scheme
from coupler.coupling.step_limit import interface_step_limit
from coupler.checkpoint import Checkpoints, Restart
from coupler.dem.timestep import dem_substeps
from coupler.errors import SceneError, SimulationError
from coupler.scene import output_stride
from coupler.results import (BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS, FLOAT_FORMAT, INTERFACE_COLUMNS,
                             MPM_BODY_COLUMNS, Result, StreamedResult,
                             append_csv, body_table, contact_table, empty, write_csv)

LOG_COLUMNS = ["t", "px_dem", "py_dem", "px_mpm", "py_mpm", "K_dem", "P_dem", "E_dem", "D_dem", "K_mpm", "P_mpm",
               "E_mpm"]


# interface tables written at every output time (coupler/vtk.py draws them as the interface series)
INTERFACE_SERIES = ("interface_series.csv", "interface_wall.csv")


def _chain_columns(chains, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per row: the chain (run of consecutive outline edges) it belongs to and whether that chain is closed."""
    chain = np.zeros(n, np.int64)
    closed = np.zeros(n, np.int64)
    for k, (a, b, c) in enumerate(chains):
        chain[a:b] = k
        closed[a:b] = int(bool(c))
    return chain, closed


def coupling_step(scene, mpm_dt: float) -> tuple[float, str]:
    """The coupling step of a scene whose MPM partition steps by mpm_dt (coupling.dt if given, else the MPM's CFL
    step): without coupling.dt an explicit MPM's step is lowered to the interface contact's stable step
    (step_limit.py) when that is smaller. Returns (dt, what set it when that limit did, else "")."""
    if scene.coupling.dt is None and scene.mpm.scheme == "explicit":
        lim, why = interface_step_limit(scene)
        if lim < mpm_dt:
            return lim, f"{why}: {lim:.4g} s < the MPM CFL step"
    return mpm_dt, ""


class CoupledRun:
    """Builds both partitions, the mapper and the scheme; `step()` one coupling step (tests and bench use it)."""

    def __init__(self, scene):
        cs = scene.coupling
        self.scene, self.cs = scene, cs
        self.mpm = MPMPartition(scene, cs.dt)
        # dt_limit: what set the coupling step when not the scene's or the MPM's CFL step
        self.mpm.sol.dt, self.dt_limit = coupling_step(scene, self.mpm.dt)
        self.dt = self.mpm.dt
        self.substeps = dem_substeps(scene, self.dt)
        for m in cs.motions:       # phases switch at the start of a coupling step (DEMPartition._apply_motions)
            for key, tm in (("start", m.start), ("until", m.until)):
                r = tm / self.dt
                if math.isfinite(tm) and abs(r - round(r)) > 1e-9 * max(1.0, r):
                    raise SceneError(f"coupling.motion.{key}", f"{tm:g} s must be a multiple of the coupling step "
                                                               f"{self.dt:g} s (phases switch between steps)")
        self.dem = dem_partition_class(cs.dem_partition)(scene, cs.wall_name, self.dt / self.substeps, cs.motions)
        geo = cs.geometry
        x_mpm = self.mpm.interface_state()["x"][geo.index]
        err = float(np.abs(x_mpm - geo.points).max())
        if err > 1e-9 * max(1.0, float(np.abs(geo.points).max())):
            raise SceneError("coupling", f"interface points differ from the MPM boundary particles by {err:.3g} m "
                                         f"(outline rule out of date in coupler/coupling/interface.py)")
        self.mapper = make_mapper(cs.mapper, geo.points, geo.chains, geo.wall_nodes)
        self.scheme = make_scheme(cs.scheme)(self.dem, self.mpm, self.mapper, geo.index, geo.wall_nodes.copy(),
                                             cs.thickness, predictor=cs.predictor)
        self.t = 0.0
        self.nstep = 0

    def step(self) -> None:
        self.scheme.step(self.t, self.dt)
        self.nstep += 1
        self.t = self.nstep * self.dt

    def interface_rows(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The interface now, both sides (INTERFACE_SERIES tables): MPM interface points (outline order; load =
        the point load of the last coupling step [N per unit depth]) and DEM wall nodes (node force = the
        time-averaged force by the spheres on the node over the last coupling step [N])."""
        geo = self.cs.geometry
        st = self.mpm.interface_state()
        x, u, v = st["x"][geo.index], st["displacement"][geo.index], st["velocity"][geo.index]
        f = getattr(self.scheme, "last_loads", None)
        f = np.zeros_like(x) if f is None else f.copy()      # the scheme's buffer: its values now
        n = len(x)
        chain, closed = _chain_columns(geo.chains, n)
        pts = pd.DataFrame({"t": np.full(n, self.t), "point": np.arange(n), "chain": chain, "closed": closed,
                            "x": x[:, 0], "y": x[:, 1], "ux": u[:, 0], "uy": u[:, 1], "vx": v[:, 0],
                            "vy": v[:, 1], "fx": f[:, 0], "fy": f[:, 1]})
        xw, vw = self.dem.interface_state()
        F = self.dem.interface_forces()
        nn = len(xw)
        chain, closed = _chain_columns(geo.wall_chains, nn)
        nodes = pd.DataFrame({"t": np.full(nn, self.t), "node": np.arange(nn), "chain": chain, "closed": closed,
                              "x": xw[:, 0], "y": xw[:, 1], "vx": vw[:, 0], "vy": vw[:, 1], "fx": F[:, 0],
                              "fy": F[:, 1]})
        return pts, nodes

    def log_row(self) -> dict:
        th = self.cs.thickness
        pd_, pm = self.dem.momentum(), self.mpm.momentum() * th
        k, p, e, d = self.dem.energies()
        em = self.mpm.energies()
        return {"t": self.t, "px_dem": pd_[0], "py_dem": pd_[1], "px_mpm": pm[0], "py_mpm": pm[1], "K_dem": k,
                "P_dem": p, "E_dem": e, "D_dem": d, "K_mpm": th * em["kinetic"], "P_mpm": th * em["potential"],
                "E_mpm": th * em["elastic"]}


class _Tables:
    """The tables of a running coupled run written at every output time (appended; results.append_csv), so that a
    run that stops (blow-up or kill) keeps every table up to its last output time, readable (issue 17). The
    finished run keeps them (run_coupled sets Result.streamed, so Result.write does not write them again: the MPM
    snapshots were written twice, ~1/4 of the output cost of coupled_retaining_wall; interface.csv was too, until
    the thirty-sixth session); coupling_log.csv is written whole at the end. write() takes one output time's rows: the run holds no row it has
    written only for these files (the interface series), and a checkpoint none of the rows that stay on disk."""

    def __init__(self, out_dir, bnames):
        self.o = Path(out_dir)
        self.o.mkdir(parents=True, exist_ok=True)
        self.bnames = bnames
        self.first = True                   # the next write starts the files (their headers)
        self.n_iface = 0                    # interface.csv rows written
        self.n_snaps = 0                    # particles_<n>.csv written
        self.last_t = float("nan")          # the last output time written

    def write(self, t, body_row, con, mpm_rows, energy_row, iface, n_iface, log_row, snap, series_rows) -> None:
        """One output time: body_row (n_bodies, 13) or None, con (i, j, data) or None, the MPM body rows, the energy
        and log rows, interface.csv up to row n_iface, the MPM snapshot (or None) and the interface series' rows."""
        o, ff, first = self.o, FLOAT_FORMAT, self.first
        if body_row is not None:
            append_csv(o / "bodies.csv", body_table([body_row], [t], self.bnames), ff["bodies"], first)
        elif first:
            append_csv(o / "bodies.csv", empty(BODY_COLUMNS), ff["bodies"], True)
        if con is not None and len(con[0]):
            ii, jj, data = con
            append_csv(o / "contacts.csv", contact_table([np.full(len(ii), t)], list(ii), list(jj), [data]),
                       ff["contacts"], first)
        elif first:
            append_csv(o / "contacts.csv", empty(CONTACT_COLUMNS), ff["contacts"], True)
        append_csv(o / "mpm_bodies.csv", pd.DataFrame(mpm_rows, columns=MPM_BODY_COLUMNS), ff["mpm_bodies"], first)
        append_csv(o / "energy.csv", pd.DataFrame([energy_row] if energy_row else [], columns=ENERGY_COLUMNS),
                   ff["energy"], first)
        append_csv(o / "interface.csv", pd.DataFrame(iface[self.n_iface:n_iface], columns=INTERFACE_COLUMNS),
                   ff["interface"], first)
        self.n_iface = n_iface
        append_csv(o / "coupling_log.csv", pd.DataFrame([log_row], columns=LOG_COLUMNS), "%.12g", first)
        if snap is not None:
            write_csv(o / f"particles_{self.n_snaps}.csv", snap, ff["particles"])
            self.n_snaps += 1
        for name, rows in zip(INTERFACE_SERIES, series_rows):
            append_csv(o / name, rows, "%.12g", first)
        self.first = False

    def stopped(self, scene, run, err) -> None:
        """summary.json of a run that stopped: what stopped it, and up to when the tables go."""
        import json
        self.o.joinpath("summary.json").write_text(json.dumps({
            "scene": scene.name, "backend": "native", "status": "stopped", "error": str(err),
            "steps": run.nstep, "t": run.t, "dt": run.dt,
            "tables_end_at_t": float(self.last_t)}, indent=2) + "\n")


def run_coupled(scene, out_dir, progress: bool = True, restart: Restart | None = None,
                keep_tables: bool = True) -> Result:
    """keep_tables = False (with out_dir): bodies, contacts and MPM snapshots are not held in memory; the returned
    StreamedResult reads them back from out_dir when used (coupler/results.py)."""
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    t_record = [0.0]                 # wall time in record(): the output times' tables, snapshots and writes
    ck = Checkpoints(restart, out_dir, scene)          # restart files (coupler/checkpoint.py)
    ck.check(dem_partition_class(scene.coupling.dem_partition))     # before a partition process is started
    saved = ck.resumed()
    names = ("run", "energy", "snaps", "log", "load_sum", "n_sum", "k0", "tables")
    if saved is None:
        run = CoupledRun(scene)
    else:
        run = saved["run"]
    ck.check(run.mpm)
    t_build = time.perf_counter() - t0
    n_steps = int(math.ceil(scene.time.t_end / run.dt - 1e-9))
    every = output_stride(scene, run.dt, "the coupling step")     # SceneError if output_interval < dt
    out = scene.output
    # this process's output rows for the returned Result; a resumed run's earlier rows stay on disk (bodies,
    # contacts, interface: Checkpoints.joined; MPM snapshots: frames_in), so a checkpoint does not grow with them
    body_rows, body_t, con_t, con_i, con_j, con_d, mpm_rows = [], [], [], [], [], [], []
    iface = np.zeros((n_steps + 1, len(INTERFACE_COLUMNS)))        # one row per coupling step (row 0: t = 0)
    if saved is None:
        energy, snaps, log = [], [], []
        load_sum, n_sum, k0 = np.zeros((len(run.cs.geometry.index), 2)), 0, 0
    else:
        _, energy, snaps, log, load_sum, n_sum, k0, tables = (saved[n] for n in names)
        iface[:k0 + 1] = ck.earlier("interface.csv").to_numpy()
    bnames = run.dem.body_names()
    if saved is None:
        tables = _Tables(out_dir, bnames) if out_dir is not None else None
    k = k0
    keep = keep_tables or out_dir is None

    def record(n_iface: int, last: bool = False):
        tr = time.perf_counter()
        t = run.t
        body = con = snap = None
        if out.bodies:
            body = run.dem.body_table()
            if keep:
                body_rows.append(body)
                body_t.append(t)
        if out.contacts:
            con = run.dem.contact_rows()
            ii, jj, data = con
            if keep:
                con_i.extend(ii)
                con_j.extend(jj)
                con_d.append(data)
                con_t.append(np.full(len(ii), t))
        mrows = run.mpm.body_rows()
        mpm_rows.extend(mrows)
        r = run.log_row()
        log.append(r)
        energy.append({"t": t, "kinetic": r["K_dem"] + r["K_mpm"], "potential": r["P_dem"] + r["P_mpm"],
                       "elastic": r["E_dem"] + r["E_mpm"], "dissipated": r["D_dem"]})
        if out.snapshot_at(len(log) - 1, scene.time.output_interval, last):
            snap = run.mpm.particles_frame()
            snaps.append((t, snap if keep else None))
        if tables is not None:
            tables.write(t, body, con, mrows, energy[-1] if out.energy else None, iface, n_iface, r, snap,
                         run.interface_rows())
            tables.last_t = t
        t_record[0] += time.perf_counter() - tr
        ck.output_done(t, k, lambda: dict(zip(names, (run, energy, ck.frames_out(snaps), log, load_sum, n_sum, k,
                                                      tables))), last)

    if saved is None:
        record(1)
    from tqdm import tqdm      # progress bar as the DEM's (stderr, after 3 s, off with progress=False)
    bar = tqdm(total=n_steps, initial=k0, disable=not progress, delay=3.0, unit="step", mininterval=1.0,
               leave=False, desc="coupled")
    tick = max(1, n_steps // 500)
    try:
        for k in range(k0 + 1, n_steps + 1):
            run.step()
            iface[k, 0] = run.t
            iface[k, 1:] = run.scheme.row[1:]
            if k > n_steps - every:
                load_sum += run.scheme.last_loads
                n_sum += 1
            if k % every == 0 or k == n_steps:
                record(k + 1, last=k == n_steps)
            if k % tick == 0 or k == n_steps:
                bar.update(k - bar.n)
    except SimulationError as e:
        if tables is not None:
            tables.stopped(scene, run, e)
        raise
    finally:
        bar.close()
        run.dem.close()               # the DEM partition's own resources (the YADE partition: its process)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    energy = pd.DataFrame(energy if out.energy else [], columns=ENERGY_COLUMNS)    # [output] energy = false:
    # the header only, as a DEM run (coupling_log.csv keeps each partition's energies)
    mpm_bodies = ck.joined("mpm_bodies.csv", pd.DataFrame(mpm_rows, columns=MPM_BODY_COLUMNS), dtype={"body": str})
    interface = pd.DataFrame(iface, columns=INTERFACE_COLUMNS)
    if keep:
        res = Result(energy=energy, mpm_bodies=mpm_bodies, interface=interface,
                     particles=ck.frames_in(snaps) if saved is not None else snaps)
        ck.dem_tables(res, out, body_rows, body_t, bnames, (con_t, con_i, con_j, con_d))
    else:
        res = StreamedResult(out_dir, {}, energy, mpm_bodies, interface)
    T = run.scheme.timers
    solvers = T["dem"] + T["mpm"]
    own = T["map"] + T["interface"] + T["exchange"]
    cs = run.cs
    res.summary = {
        "scene": scene.name, "backend": "native", "wall_time_s": wall, "steps": n_steps, "dt": run.dt,
        "particles": run.dem.n_spheres() + run.mpm.n_points(),
        "coupling": {
            "scheme": cs.scheme, "predictor": cs.predictor, "mapper": cs.mapper, "dem_partition": cs.dem_partition,
            "thickness": cs.thickness, "interface_body": cs.body, "interface_edges": cs.edges,
            "interface_points": int(len(cs.geometry.index)),
            "wall_nodes": int(len(cs.geometry.wall_nodes)), "coupling_dt": run.dt, "dem_substeps": run.substeps,
            "interface_start_overlap": {**cs.start_overlap, "tolerance": scene.dem.max_initial_overlap,
                                        "note": ("the DEM spheres' overlap at t = 0 with the interface wall, the chain "
                                                 "through the boundary particles, which cuts the outline's corners "
                                                 "(against the outline itself the scene allows at most the "
                                                 "tolerance: coupling/scene.py start_overlap)")},
            "coupling_dt_limited_by": run.dt_limit or "the scene (coupling.dt) or the MPM CFL step",
            **run.dem.info(), **run.mpm.info(), "dropped_load_steps": run.scheme.dropped_steps,
            "energy_columns": ("DEM [J] + MPM [J/m] x thickness; dissipated = DEM contacts only (MPM plastic and "
                               "numerical dissipation not integrated)"),
            "cost_s": {"build": t_build, **T, "output": t_record[0]},
            "cost_note": ("wall times [s]; output = record() at the output times (state reads, tables, MPM snapshots "
                          "and their CSV writes); the end-of-run writes and the ParaView series come after "
                          "(run_scene: Result.write); cpu_time_s = this process's CPU time over the run, all threads"),
            "cpu_time_s": cpu,
            "cost_per_step_us": {k: 1e6 * v / max(1, n_steps) for k, v in T.items()},
            "coupling_own_fraction": own / solvers if solvers > 0 else float("nan"),
            "coupling_own_note": ("map = mapper kinematics + forces with the load assembly (compiled, "
                                  "coupling/exchange.py); interface = wall node update (DEMPartition.set_interface, "
                                  "compiled); exchange = state reads, dropped-load accounting, work, interface.csv "
                                  "row"),
        },
        **ck.summary(),
    }
    if out_dir is not None:
        o = Path(out_dir)
        o.mkdir(parents=True, exist_ok=True)
        write_csv(o / "coupling_log.csv", pd.DataFrame(log, columns=LOG_COLUMNS), "%.12g")
        geo = run.cs.geometry
        u = run.mpm.interface_state()["displacement"][geo.index]
        pd.DataFrame({"x0": geo.points[:, 0], "y0": geo.points[:, 1], "ux": u[:, 0], "uy": u[:, 1],
                      "fx": load_sum[:, 0] / max(1, n_sum), "fy": load_sum[:, 1] / max(1, n_sum)}).to_csv(
            o / "interface_points.csv", index=False, float_format="%.12g")
        # bodies / contacts / energy, the MPM snapshots and the interface series were written as the run went
        # (_Tables, the same bytes as a whole-table write): Result.write does not write them a second time
        res.streamed = o.resolve()
    return res
