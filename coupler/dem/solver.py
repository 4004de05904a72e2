"""Native DEM solver: state arrays built from the scene, the time loop, health checks and result tables.

One step (velocity Verlet): kick_drift -> [rebuild neighbour lists if a sphere moved > skin/2] -> forces -> kick.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from coupler import __version__
from coupler.dem import forces as fk
from coupler.dem.contact import law_table
from coupler.dem import integrator as it
from coupler.dem import clusters as cl
from coupler.dem import meshes as msh
from coupler.dem.advance import _max_disp_sq, advance_clusters_par, advance_clusters_ser, advance_par, advance_ser
from coupler.dem.neighbors import build_pairs, carry_pair_state, default_skin
from coupler.dem.scene import DEMScene, smallest_radius
from coupler.dem.timestep import chosen_dt, stable_dt
from coupler.errors import SimulationError
from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS, Result
from coupler.scene import Scene


PARALLEL_MIN_SPHERES = 4000
HEALTH_EVERY = 20000          # steps between NaN / domain checks when outputs are further apart


@dataclass
class Spheres:
    """Flat struct-of-arrays state of all spheres (free spheres and, later, cluster members)."""
    x: np.ndarray
    v: np.ndarray
    w: np.ndarray
    q: np.ndarray
    f: np.ndarray
    t: np.ndarray
    r: np.ndarray
    mass: np.ndarray
    mdamp: np.ndarray      # effective mass used in contact damping (is `mass` for free spheres)
    mat: np.ndarray        # int16 material index
    body: np.ndarray       # int32 cluster index, -1 for a free sphere
    names: list[str]

    @property
    def n(self) -> int:
        return self.x.shape[0]

    def nbytes(self) -> int:
        arrs = [self.x, self.v, self.w, self.q, self.f, self.t, self.r, self.mass, self.mat, self.body]
        if self.mdamp is not self.mass:
            arrs.append(self.mdamp)
        return sum(a.nbytes for a in arrs)


@dataclass
class Planes:
    names: list[str]
    point: np.ndarray
    normal: np.ndarray
    vel: np.ndarray
    mat: np.ndarray


@dataclass
class Contacts:
    """Neighbour lists and per-contact state (pairs CSR by i; plane candidates CSR by sphere)."""
    offsets: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    jstart: np.ndarray
    jlist: np.ndarray
    pstate: np.ndarray
    pout: np.ndarray
    woff: np.ndarray
    wid: np.ndarray
    wstate: np.ndarray
    wout: np.ndarray
    x_ref: np.ndarray
    t_ref: float = 0.0
    rebuilds: int = 0


@dataclass
class EnergyLog:
    rows: list = field(default_factory=list)
    e0: float | None = None
    p0: float = 0.0
    scale: float = 0.0


class DEMSolver:
    """Steps a DEM scene. `step()` advances one dt; the coupler drives it the same way."""

    def __init__(self, scene: Scene):
        dem: DEMScene = scene.dem
        self.scene = scene
        self.planar = scene.dimension == 2
        self.materials = list(scene.materials.values())
        mat_index = {m.name: k for k, m in enumerate(self.materials)}
        self.table = law_table(self.materials, scene.contacts)
        self.gravity = np.array(scene.gravity_at(0.0), dtype=float)    # updated in place by a gravity schedule
        sched = scene.gravity_schedule
        self.gravity_until = float(sched[-1, 0]) if sched is not None else -math.inf
        self.dt = chosen_dt(scene)
        self.dt_limit, self.dt_reason = stable_dt(scene)
        self.skin = dem.skin if dem.skin is not None else default_skin(smallest_radius(dem))

        n = dem.n_spheres
        rho = np.array([scene.materials[m].density for m in dem.material])
        r = dem.radius.astype(float).copy()
        mass = rho * 4.0 / 3.0 * np.pi * r ** 3
        q = np.zeros((n, 4))
        q[:, 0] = 1.0
        self.s = Spheres(x=dem.position.astype(float).copy(), v=dem.velocity.astype(float).copy(),
                         w=dem.angular_velocity.astype(float).copy(), q=q, f=np.zeros((n, 3)), t=np.zeros((n, 3)),
                         r=r, mass=mass, mdamp=mass, mat=np.array([mat_index[m] for m in dem.material], np.int16),
                         body=np.full(n, -1, np.int32), names=list(dem.names))
        self.n_free = n
        self.bodies = build_bodies(scene, self.s, mat_index) if dem.clusters else None
        n = self.s.n
        pl = dem.planes
        self.planes = Planes(names=[p.name for p in pl],
                             point=np.array([p.point for p in pl], float).reshape(-1, 3),
                             normal=np.array([p.normal for p in pl], float).reshape(-1, 3),
                             vel=np.array([p.velocity for p in pl], float).reshape(-1, 3),
                             mat=np.array([mat_index[p.material] for p in pl], np.int16))
        self.meshes = [msh.build_mesh(m.name, mat_index[m.material], m.vertices, m.faces, m.velocity, n)
                       for m in dem.meshes]
        self.walls_move = bool(np.any(self.planes.vel != 0.0)) or any(np.any(m.v != 0.0) for m in self.meshes)
        self.wall_speed = max([float(np.linalg.norm(self.planes.vel, axis=1).max()) if len(pl) else 0.0]
                              + [float(np.linalg.norm(m.v, axis=1).max()) for m in self.meshes])
        # parallel kernels only pay off above a few thousand spheres (thread launch costs ~50 us per kernel)
        from numba import get_num_threads
        self.parallel = get_num_threads() > 1 and n >= PARALLEL_MIN_SPHERES
        self.t0_time = 0.0
        self.track_energy = scene.output.energy
        self.diss = np.zeros(n if self.track_energy else 1)
        self.time = 0.0
        self.nstep = 0
        self.c: Contacts | None = None
        self._rebuild()
        self._forces()
        if self.bodies is not None:
            B = self.bodies
            cl.reduce_to_bodies(B.c, B.mass, self.gravity, B.member, B.owner, self.s.x, self.s.f, self.s.t, B.F, B.T)
            self._qtmp, self._wtmp = B.q.copy(), B.w.copy()
        self.domain = self._domain()

    # -- neighbour lists -----------------------------------------------------------------------------------
    def _rebuild(self) -> None:
        s = self.s
        offsets, pi, pj, jstart, jlist = build_pairs(s.x, s.r, s.body, self.skin)
        pstate = np.zeros((len(pj), fk.widths(self.table)[0]))
        woff = np.zeros(s.n + 1, np.int32)
        wid = fk.plane_candidates(s.x, s.r, self.planes.point, self.planes.normal, self.skin, woff)
        wstate = np.zeros((len(wid), fk.widths(self.table)[0]))
        self.mesh_cand = [msh.candidates(s.x, s.r, m, self.skin) for m in self.meshes]
        self.mesh_out = [np.zeros((0, 7)) for _ in self.meshes]
        old = self.c
        if old is not None:
            carry_pair_state(s.n, old.offsets, old.pj, offsets, pj, old.pstate, pstate)
            fk.carry_wall_state(s.n, old.woff, old.wid, woff, wid, old.wstate, wstate)
        self.c = Contacts(offsets=offsets, pi=pi, pj=pj, jstart=jstart, jlist=jlist, pstate=pstate,
                          pout=np.zeros((len(pj), fk.widths(self.table)[1])), woff=woff, wid=wid, wstate=wstate,
                          wout=np.zeros((len(wid), fk.widths(self.table)[1])), x_ref=s.x.astype(np.float32), t_ref=self.time,
                          rebuilds=(old.rebuilds + 1) if old is not None else 0)

    # -- stepping ------------------------------------------------------------------------------------------
    def _forces(self) -> None:
        s, c, p = self.s, self.c, self.planes
        pair_forces = fk.pair_forces_par if self.parallel else fk.pair_forces_ser
        gather = fk.gather_par if self.parallel else fk.gather_ser
        pair_forces(s.x, s.v, s.w, s.r, s.mdamp, s.mat, c.pi, c.pj, c.pstate, self.table, self.dt, c.pout)
        gather(s.x, s.v, s.w, s.r, s.mass, s.mdamp, s.mat, s.body, self.gravity, c.offsets, c.jstart, c.jlist,
               c.pout, c.woff, c.wid, c.wstate, c.wout, p.point, p.normal, p.vel, p.mat, self.table,
               self.dt, s.f, s.t, self.diss, self.track_energy)
        for k, m in enumerate(self.meshes):
            off, cand = self.mesh_cand[k]
            buf = np.zeros((max(16, 4 * len(cand)), 7))
            nout = msh.mesh_forces(s.x, s.v, s.w, s.r, s.mdamp, s.mat, m.mat, m.x, m.v, m.faces, m.face_edges, off,
                                   cand, m.slots, self.table, self.dt, s.f, s.t, m.node_force, self.diss,
                                   self.track_energy, buf)
            self.mesh_out[k] = buf[:nout]

    def set_mesh_nodes(self, name: str, x: np.ndarray, v: np.ndarray) -> None:
        """Prescribe node positions and velocities of a mesh wall (the coupler calls this every step)."""
        m = next(m for m in self.meshes if m.name == name)
        m.x[:] = x
        m.v[:] = v

    def mesh_node_forces(self, name: str) -> np.ndarray:
        """Forces exerted by the spheres on the nodes of a mesh at the last step (barycentric distribution)."""
        return next(m for m in self.meshes if m.name == name).node_force.copy()

    def _finish_step(self) -> None:
        """After a drift that asked for a rebuild: rebuild, forces, (bodies), second half kick."""
        s, B = self.s, self.bodies
        self._rebuild()
        self._forces()
        if B is not None:
            cl.reduce_to_bodies(B.c, B.mass, self.gravity, B.member, B.owner, s.x, s.f, s.t, B.F, B.T)
            cl.body_kick(B.v, B.L, B.F, B.T, B.mass, self.dt, self.planar)
            cl.omega_from_L(B.q, B.L, B.Ip, B.w)
            cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, s.x, s.v, s.w)
        kick = it.kick_par if self.parallel else it.kick_ser
        kick(s.v, s.w, s.f, s.t, s.mass, s.r, s.body, self.dt, self.planar)

    def advance(self, nsteps: int) -> None:
        """Advance nsteps steps. While a gravity schedule runs, one step at a time with g(t_{n+1}) (the forces
        of velocity Verlet are evaluated at the end of the step)."""
        while nsteps > 0 and self.time < self.gravity_until:
            self.gravity[:] = self.scene.gravity_at(self.time + self.dt)
            self._advance(1)
            nsteps -= 1
        if nsteps > 0:
            self._advance(nsteps)

    def _advance(self, nsteps: int) -> None:
        """Advance nsteps steps in a compiled loop (Python only at neighbour-list rebuilds); scenes with mesh
        walls take the Python step loop."""
        if self.meshes:
            self._advance_general(nsteps)
            return
        s, p, B = self.s, self.planes, self.bodies
        done = 0
        while done < nsteps:
            c = self.c
            args = (nsteps - done, s.x, s.v, s.w, s.q, s.f, s.t, s.r, s.mass, s.mdamp,
                    s.mat, s.body, self.gravity, self.planar, self.dt, c.pi, c.pj, c.offsets,
                    c.jstart, c.jlist, c.pstate, c.pout, c.woff, c.wid, c.wstate, c.wout, p.point,
                    p.normal, p.vel, p.mat, self.table, self.diss, self.track_energy, c.x_ref,
                    (0.5 * self.skin) ** 2, self.wall_speed, self.time - c.t_ref)
            if B is None:
                k, stopped = (advance_par if self.parallel else advance_ser)(*args)
            else:
                fused = advance_clusters_par if self.parallel else advance_clusters_ser
                k, stopped = fused(*args, B.c, B.q, B.v, B.L, B.w, B.mass, B.Ip, B.F, B.T, B.member, B.owner,
                                   B.offset, self._qtmp, self._wtmp)
            self.nstep += k + stopped
            self.time = self.t0_time + self.nstep * self.dt
            done += k + stopped
            if stopped:
                self._finish_step()

    def step(self) -> None:
        self.advance(1)

    def _advance_general(self, nsteps: int) -> None:
        """Steps with mesh walls (and maybe clusters): Python loop around compiled kernels."""
        s, B, dt, p = self.s, self.bodies, self.dt, self.planes
        for _ in range(nsteps):
            it.kick_drift_ser(s.x, s.v, s.w, s.q, s.f, s.t, s.mass, s.r, s.body, dt, self.planar)
            if B is not None:
                cl.body_kick(B.v, B.L, B.F, B.T, B.mass, dt, self.planar)
                cl.body_drift(B.c, B.q, B.v, B.L, B.Ip, B.w, dt, self._qtmp, self._wtmp)
                cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, s.x, s.v, s.w)
            p.point += p.vel * dt
            for m in self.meshes:
                m.x += m.v * dt
            self.nstep += 1
            self.time = self.t0_time + self.nstep * dt
            c = self.c
            disp = math.sqrt(_max_disp_sq(s.x, c.x_ref)) + self.wall_speed * (self.time - c.t_ref)
            if disp > 0.5 * self.skin:
                self._rebuild()
            self._forces()
            if B is not None:
                cl.reduce_to_bodies(B.c, B.mass, self.gravity, B.member, B.owner, s.x, s.f, s.t, B.F, B.T)
                cl.body_kick(B.v, B.L, B.F, B.T, B.mass, dt, self.planar)
                cl.omega_from_L(B.q, B.L, B.Ip, B.w)
                cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, s.x, s.v, s.w)
            it.kick_ser(s.v, s.w, s.f, s.t, s.mass, s.r, s.body, dt, self.planar)

    # -- health --------------------------------------------------------------------------------------------
    def _domain(self) -> tuple[np.ndarray, np.ndarray]:
        if self.scene.domain is not None:
            return self.scene.domain
        x = self.s.x
        lo, hi = x.min(axis=0), x.max(axis=0)
        size = max(float((hi - lo).max()), 1.0)
        return lo - 10.0 * size, hi + 10.0 * size

    def check_health(self) -> None:
        s = self.s
        for name, arr in (("position", s.x), ("velocity", s.v), ("angular velocity", s.w)):
            bad = ~np.isfinite(arr).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                raise SimulationError(self.nstep, self.time, s.names[i], name, "is not finite (NaN or inf)")
        lo, hi = self.domain
        out = ((s.x < lo) | (s.x > hi)).any(axis=1)
        if out.any():
            i = int(np.argmax(out))
            raise SimulationError(self.nstep, self.time, s.names[i], "position",
                                  f"{s.x[i].tolist()} left the domain [{lo.tolist()}, {hi.tolist()}]")

    # -- observables ---------------------------------------------------------------------------------------
    def energies(self) -> tuple[float, float, float, float]:
        s, c = self.s, self.c
        free = s.body < 0
        inertia = 0.4 * s.mass * s.r ** 2
        kin = 0.5 * float(np.sum((s.mass * np.einsum("ij,ij->i", s.v, s.v))[free])
                          + np.sum((inertia * np.einsum("ij,ij->i", s.w, s.w))[free]))
        pot = -float(np.sum((s.mass * (s.x @ self.gravity))[free]))
        if self.bodies is not None:
            kin += self.bodies.kinetic()
            pot -= float(np.sum(self.bodies.mass * (self.bodies.c @ self.gravity)))
        el = float(c.pstate[:, 3].sum() + c.wstate[:, 3].sum())
        diss = float(self.diss.sum()) if self.track_energy else float("nan")
        return kin, pot, el, diss

    def body_names(self) -> list[str]:
        names = self.s.names[:self.n_free]
        return names + (self.bodies.names if self.bodies is not None else [])

    def body_table(self) -> np.ndarray:
        s, k = self.s, self.n_free
        rows = np.hstack([s.x[:k], s.v[:k], s.q[:k], s.w[:k]])
        if self.bodies is not None:
            B = self.bodies
            rows = np.vstack([rows, np.hstack([B.c, B.v, B.reported_q(), B.w])])
        return rows

    def contact_rows(self) -> tuple[list[str], list[str], np.ndarray]:
        s, c = self.s, self.c
        act = np.nonzero(c.pout[:, 8] > 0.0)[0]
        names = np.array(s.names, dtype=object)
        ii = list(names[c.pi[act]])
        jj = list(names[c.pj[act]])
        data = [np.column_stack([c.pout[act, 0:3], c.pout[act, 6:9]])]
        wact = np.nonzero(c.wout[:, 8] > 0.0)[0]
        if len(wact):
            owner = np.repeat(np.arange(s.n), np.diff(c.woff))
            ii += list(names[owner[wact]])
            jj += [f"wall:{self.planes.names[k]}" for k in c.wid[wact]]
            data.append(np.column_stack([c.wout[wact, 0:3], c.wout[wact, 6:9]]))
        for m, o in zip(self.meshes, self.mesh_out):
            if len(o):
                ii += list(names[o[:, 0].astype(int)])
                jj += [f"wall:{m.name}"] * len(o)
                data.append(o[:, 1:7])
        return ii, jj, np.vstack(data)

    def memory_bytes(self) -> dict[str, int]:
        c = self.c
        contacts = sum(a.nbytes for a in (c.pi, c.pj, c.jlist, c.pstate, c.pout, c.wid, c.wstate, c.wout))
        per_sphere = self.s.nbytes() + c.x_ref.nbytes + c.offsets.nbytes + c.jstart.nbytes + c.woff.nbytes
        return {"spheres": per_sphere, "contacts": contacts}


def run_dem(scene: Scene, out_dir: Path | None = None, progress: bool = True) -> Result:
    """Run a DEM-only scene to t_end and return the result tables."""
    from tqdm import tqdm
    t0 = time.perf_counter()
    solver = DEMSolver(scene)
    dt = solver.dt
    n_steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    out = scene.output
    body_rows: list[np.ndarray] = []
    body_t: list[float] = []
    con_t: list[np.ndarray] = []
    con_i: list[str] = []
    con_j: list[str] = []
    con_d: list[np.ndarray] = []
    elog = EnergyLog()

    def record():
        solver.check_health()
        t = solver.time
        if out.bodies:
            body_rows.append(solver.body_table())
            body_t.append(t)
        if out.contacts:
            ii, jj, data = solver.contact_rows()
            con_i.extend(ii)
            con_j.extend(jj)
            con_d.append(data)
            con_t.append(np.full(len(ii), t))
        if out.energy:
            k, p, e, d = solver.energies()
            elog.rows.append((t, k, p, e, d))
            _check_energy(solver, elog, k, p, e, d)

    record()
    bar = tqdm(total=n_steps, disable=not progress, delay=3.0, unit="step", mininterval=1.0, leave=False)
    step = 0
    while step < n_steps:
        chunk = min(every - (step % every), n_steps - step, HEALTH_EVERY)
        solver.advance(chunk)
        step += chunk
        bar.update(chunk)
        if step % every == 0 or step == n_steps:
            record()
        else:
            solver.check_health()
    bar.close()
    wall = time.perf_counter() - t0

    res = Result()
    s = solver.s
    if body_rows:
        bnames = solver.body_names()
        nb = len(bnames)
        arr = np.vstack(body_rows)
        df = pd.DataFrame(arr, columns=BODY_COLUMNS[2:])
        df.insert(0, "body", np.tile(np.array(bnames, dtype=object), len(body_rows)))
        df.insert(0, "t", np.repeat(np.array(body_t), nb))
        res.bodies = df
    if con_d and sum(len(d) for d in con_d):
        data = np.vstack(con_d)
        res.contacts = pd.DataFrame({"t": np.concatenate(con_t), "i": con_i, "j": con_j,
                                     "fx": data[:, 0], "fy": data[:, 1], "fz": data[:, 2], "fn": data[:, 3],
                                     "ft": data[:, 4], "overlap": data[:, 5]})[CONTACT_COLUMNS]
    if elog.rows:
        res.energy = pd.DataFrame(elog.rows, columns=ENERGY_COLUMNS)
    mem = solver.memory_bytes()
    res.summary = {
        "scene": scene.name, "backend": "native", "code_version": f"mpmdem {__version__}",
        "wall_time_s": wall, "steps": solver.nstep, "dt": dt, "particles": s.n,
        "dt_limit": solver.dt_limit, "dt_limit_reason": solver.dt_reason, "skin": solver.skin,
        "neighbour_rebuilds": solver.c.rebuilds, "memory_bytes": mem,
        "damping_beta": {f"{a}-{b}": float(solver.table[i, j, 2]) for i, a in enumerate(m.name for m in solver.materials)
                         for j, b in enumerate(m.name for m in solver.materials) if i <= j and np.isfinite(solver.table[i, j, 2])},
        "contact_law": {f"{k[0]}-{k[1]}": {"restitution": v.restitution, "friction": v.friction,
                                           "damping": v.damping, "tangential_history": v.tangential_history}
                        for k, v in scene.contacts.items()},
        "wall_effective_radius": "R (sphere radius), wall effective mass = sphere mass",
    }
    if solver.bodies is not None:
        res.summary["clusters"] = {
            "count": len(solver.bodies.names),
            "damping_effective_mass": scene.dem.cluster_damping_mass,
            "damping_effective_mass_meaning": ("body: m* uses the cluster mass (LIGGGHTS multisphere)"
                                               if scene.dem.cluster_damping_mass == "body" else
                                               "sphere: m* uses the member sphere mass (YADE clumps)"),
            "mass_property_error_max": float(solver.bodies.mass_error.max()),
        }
    if out_dir is not None:
        res.write(out_dir)
    return res


def _check_energy(solver: DEMSolver, elog: EnergyLog, k: float, p: float, e: float, d: float) -> None:
    """Energy jump detection: with static walls, K + P + E_el + D may not grow by more than 10 % of the energy scale."""
    total = k + p + e + d
    if elog.e0 is None:
        elog.e0 = total
        elog.p0 = p
    elog.scale = max(elog.scale, k + e, elog.p0 - p, 1e-300)
    if solver.time <= solver.gravity_until:     # gravity still changing: P is not a potential yet
        elog.e0 = None
        return
    if solver.walls_move or not math.isfinite(total):
        return
    if total - elog.e0 > 0.1 * elog.scale:
        raise SimulationError(solver.nstep, solver.time, "<all>", "total energy",
                              f"grew by {total - elog.e0:.4g} J (scale {elog.scale:.4g} J): unstable time step "
                              f"(dt = {solver.dt:.3g}, stable limit {solver.dt_limit:.3g}) or bad input")


def build_bodies(scene: Scene, s: Spheres, mat_index: dict) -> "cl.Bodies":
    """Append the member spheres of every cluster to `s` (in place) and return the body state."""
    dem = scene.dem
    names, cs, qs, qrefs, vs, Ls, ws, ms, Ips, errs = [], [], [], [], [], [], [], [], [], []
    add_x, add_r, add_m, add_md, add_mat, add_body, add_names, member_off = [], [], [], [], [], [], [], []
    for b, c in enumerate(dem.clusters):
        t = dem.templates[c.template]
        mat = scene.materials[c.material]
        path = f"dem.templates.{c.template}"
        mp = cl.mass_properties(t, mat.density, path)
        Ip, R0 = mp.principal()
        qref = cl.quat_from_matrix(R0)
        qb = cl.quat_mul(c.orientation, qref)
        Rb = _quat_matrix(qb)
        d_p = (t.offsets - mp.center) @ R0                  # member centres in the principal frame
        Iw = Rb @ np.diag(Ip) @ Rb.T
        names.append(c.name)
        cs.append(c.position)
        qs.append(qb)
        qrefs.append(qref)
        vs.append(c.velocity)
        ws.append(c.angular_velocity)
        Ls.append(Iw @ c.angular_velocity)
        ms.append(mp.mass)
        Ips.append(Ip)
        errs.append(mp.error)
        m_sph = mat.density * 4.0 / 3.0 * np.pi * t.radii ** 3
        add_x.append(c.position + d_p @ Rb.T)
        add_r.append(t.radii)
        add_m.append(m_sph)
        add_md.append(np.full(len(t.radii), mp.mass) if dem.cluster_damping_mass == "body" else m_sph)
        add_mat.append(np.full(len(t.radii), mat_index[c.material], np.int16))
        add_body.append(np.full(len(t.radii), b, np.int32))
        add_names += [c.name] * len(t.radii)
        member_off.append(d_p)
    n0 = s.n
    nm = sum(len(r) for r in add_r)
    s.x = np.vstack([s.x] + add_x)
    s.v = np.vstack([s.v, np.zeros((nm, 3))])
    s.w = np.vstack([s.w, np.zeros((nm, 3))])
    s.q = np.vstack([s.q, np.tile([1.0, 0.0, 0.0, 0.0], (nm, 1))])
    s.f = np.zeros((n0 + nm, 3))
    s.t = np.zeros((n0 + nm, 3))
    s.r = np.concatenate([s.r] + add_r)
    s.mdamp = np.concatenate([s.mass] + add_md)
    s.mass = np.concatenate([s.mass] + add_m)
    s.mat = np.concatenate([s.mat] + add_mat)
    s.body = np.concatenate([s.body] + add_body)
    s.names = s.names + add_names
    nb = len(names)
    B = cl.Bodies(names=names, c=np.array(cs, float), q=np.array(qs), q_ref=np.array(qrefs), v=np.array(vs, float),
                  L=np.array(Ls, float), w=np.array(ws, float), mass=np.array(ms), Ip=np.array(Ips),
                  F=np.zeros((nb, 3)), T=np.zeros((nb, 3)), member=np.arange(n0, n0 + nm, dtype=np.int64),
                  owner=np.concatenate(add_body).astype(np.int64), offset=np.vstack(member_off),
                  mass_error=np.array(errs))
    cl.omega_from_L(B.q, B.L, B.Ip, B.w)
    cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, s.x, s.v, s.w)
    return B


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
