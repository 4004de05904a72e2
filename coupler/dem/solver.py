"""Native DEM solver: state arrays built from the scene, the time loop, health checks and result tables.

One step (velocity Verlet): kick_drift -> [rebuild neighbour lists if a sphere moved > skin/2] -> forces -> kick.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from coupler import __version__
from coupler.dem import forces as fk
from coupler.dem.contact import law_table
from coupler.dem import clusters as cl
from coupler.dem import meshes as msh
from coupler.dem import state
from coupler.dem.advance import RUN_STEPS, forces_only
from coupler.dem.neighbors import build_pairs, carry_pair_state, default_skin
from coupler.dem.scene import DEMScene, smallest_radius
from coupler.dem.timestep import chosen_dt, stable_dt
from coupler.checkpoint import Checkpoints, Restart
from coupler.errors import SimulationError
from coupler.results import ENERGY_COLUMNS, Result, ResultStream, StreamedResult, body_table, contact_table, empty
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
    """Steps a DEM scene; the coupler drives it through the step contract (see the README, "DEM solver contract"):
    set_time_step, advance / advance_to, set_mesh_nodes, mesh_node_forces, mesh_work, set_body_motion."""

    def __init__(self, scene: Scene):
        dem: DEMScene = scene.dem
        self.scene = scene
        self.planar = scene.dimension == 2
        self.materials = list(scene.materials.values())
        mat_index = {m.name: k for k, m in enumerate(self.materials)}
        # rigid walls (`rigid = true`): a copy of the wall material with E = inf, so E* = E_s / (1 - nu_s^2) and
        # G* from the sphere alone; the copy keeps the name, so the pair's [[contacts]] law applies (rigid_index)
        rigid_index = {}
        for w in list(dem.planes) + list(dem.meshes):
            if w.rigid and w.material not in rigid_index:
                rigid_index[w.material] = len(self.materials)
                self.materials.append(dataclasses.replace(scene.materials[w.material], young=math.inf))
        self.table = law_table(self.materials, scene.contacts)

        def wall_mat(w) -> int:
            return rigid_index[w.material] if w.rigid else mat_index[w.material]

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
                             mat=np.array([wall_mat(p) for p in pl], np.int16))
        self.meshes = [msh.build_mesh(m.name, wall_mat(m), m.vertices, m.faces, m.velocity, n)
                       for m in dem.meshes]
        self._mesh_bins: list = [None] * len(self.meshes)   # per mesh: its FaceBins (_mesh_candidates)
        self._M = _pack_meshes(self.meshes, n)
        # parallel kernels only pay off above a few thousand spheres (thread launch costs ~50 us per kernel)
        from numba import get_num_threads
        self.parallel = get_num_threads() > 1 and n >= PARALLEL_MIN_SPHERES
        self.t0_time = 0.0
        self._steps_since_dt = 0
        self.track_energy = scene.output.energy
        self.diss = np.zeros(n if self.track_energy else 1)
        self._dmax = np.zeros(max(1, -(-n // 256)))
        self._wall_work = np.zeros(1)        # work done by the moving planes on the spheres [J]
        self.time = 0.0
        self.nstep = 0
        self.c: Contacts | None = None
        self._S = state.Spheres(*(getattr(self.s, k) for k in state.Spheres._fields))
        self._B = _pack_bodies(self.bodies)
        self._rebuild()
        self._forces()
        self._node_avg: np.ndarray | None = None
        self._motion_until = np.full(len(self._B.motion), math.inf)
        for b, c in enumerate(dem.clusters):
            if c.motion is not None:
                self.set_body_motion(c.name, c.motion.kind, c.motion.velocity, c.motion.angular_velocity)
                self._motion_until[b] = c.motion.until
        self.domain = self._domain()

    def __getstate__(self) -> dict:
        """Pickled into a run checkpoint without the binned mesh faces: rebuilt from the nodes (the same bins)."""
        return {**self.__dict__, "_mesh_bins": [None] * len(self.meshes)}

    def __setstate__(self, state: dict) -> None:
        """Unpickled from a run checkpoint (coupler/checkpoint.py): the parallel kernels follow this process's
        thread count (the results are the same bits on any), and the meshes' views into the packed mesh arrays
        (_pack_meshes) are views again."""
        from numba import get_num_threads
        self.__dict__.update(state)
        self.parallel = get_num_threads() > 1 and self.s.n >= PARALLEL_MIN_SPHERES
        M = self._M                     # pickle copies views apart: each Mesh views the packed arrays again
        for k, m in enumerate(self.meshes):
            sl = slice(M.noff[k], M.noff[k + 1])
            m.x, m.v, m.node_force, m.slots = M.x[sl], M.v[sl], M.node_force[sl], M.slots[k]

    @property
    def walls_move(self) -> bool:
        return bool(np.any(self.planes.vel != 0.0)) or bool(np.any(self._M.v != 0.0))

    # -- state handed to the kernels ------------------------------------------------------------------------
    def _W(self) -> state.Planes:
        p = self.planes
        return state.Planes(p.point, p.normal, p.vel, p.mat, self._plane_ref, bool(np.any(p.vel != 0.0)))

    def _C(self) -> state.Lists:
        c = self.c
        return state.Lists(c.offsets, c.pi, c.pj, c.jstart, c.jlist, c.pstate, c.pout, c.woff, c.wid, c.wstate,
                           c.wout, c.x_ref)

    def _P(self) -> state.Params:
        return state.Params(float(self.dt), self.planar, self.gravity, self.table, self.track_energy, self.diss,
                            (0.5 * self.skin) ** 2, self._dmax, self._wall_work)

    # -- neighbour lists -----------------------------------------------------------------------------------
    def _rebuild(self) -> None:
        s, M = self.s, self._M
        offsets, pi, pj, jstart, jlist = build_pairs(s.x, s.r, s.body, self.skin)
        pstate = np.zeros((len(pj), fk.widths(self.table)[0]))
        woff = np.zeros(s.n + 1, np.int32)
        wid = fk.plane_candidates(s.x, s.r, self.planes.point, self.planes.normal, self.skin, woff)
        wstate = np.zeros((len(wid), fk.widths(self.table)[0]))
        old = self.c
        if old is not None:
            carry_pair_state(s.n, old.offsets, old.pj, offsets, pj, old.pstate, pstate)
            fk.carry_wall_state(s.n, old.woff, old.wid, woff, wid, old.wstate, wstate)
        self.c = Contacts(offsets=offsets, pi=pi, pj=pj, jstart=jstart, jlist=jlist, pstate=pstate,
                          pout=np.zeros((len(pj), fk.widths(self.table)[1])), woff=woff, wid=wid, wstate=wstate,
                          wout=np.zeros((len(wid), fk.widths(self.table)[1])), x_ref=s.x.astype(np.float32), t_ref=self.time,
                          rebuilds=(old.rebuilds + 1) if old is not None else 0)
        self._plane_ref = self.planes.point.copy()
        if self.meshes:
            self._M = _mesh_candidates(M, s.x, s.r, self.skin, self._mesh_bins, self.parallel)

    # -- stepping ------------------------------------------------------------------------------------------
    def _forces(self) -> None:
        forces_only(self._S, self._W(), self._C(), self._B, self._M, self._P())

    @property
    def mesh_out(self) -> list[np.ndarray]:
        """Per mesh, the contact rows of the last step: sphere, fx, fy, fz, fn, ft, overlap."""
        M = self._M
        return [M.out[k, :M.nout[k]] for k in range(len(self.meshes))]

    def _mesh(self, name: str) -> int:
        for k, m in enumerate(self.meshes):
            if m.name == name:
                return k
        raise KeyError(f"no mesh wall named {name!r} (meshes: {', '.join(m.name for m in self.meshes) or 'none'})")

    def set_mesh_nodes(self, name: str, x: np.ndarray, v: np.ndarray) -> None:
        """Node positions now and node velocities used while stepping (the nodes drift x += v dt each step). The
        actual node displacement since the last neighbour build feeds the rebuild test; the work of the contact
        forces over a jump of the nodes (x given here minus x before) is added to mesh_work with the node forces
        of the last step."""
        k = self._mesh(name)
        m = self.meshes[k]
        x = np.asarray(x, float)
        v = np.asarray(v, float)
        if x.shape != m.x.shape or v.shape != m.v.shape:
            raise ValueError(f"set_mesh_nodes({name!r}): x and v must have shape {m.x.shape}, got {x.shape}, "
                             f"{v.shape}")
        if not (np.isfinite(x).all() and np.isfinite(v).all()):
            raise ValueError(f"set_mesh_nodes({name!r}): x and v must be finite")
        self._M.work[k] += float(np.sum(m.node_force * (x - m.x)))
        m.x[:] = x
        m.v[:] = v

    def mesh_node_forces(self, name: str, average: bool = True) -> np.ndarray:
        """(nnode, 3) force exerted by the spheres on the nodes of a mesh (barycentric distribution of every contact
        force). average = True: the time average over the steps of the last advance / advance_to call, impulse /
        duration with the impulse velocity Verlet delivers (trapezoid: the forces at the start and the end of the
        call count half); before any advance, the forces of the current state. average = False: the forces of
        the last step."""
        k = self._mesh(name)
        M = self._M
        if average and self._node_avg is not None:
            return self._node_avg[M.noff[k]:M.noff[k + 1]].copy()
        return self.meshes[k].node_force.copy()

    def mesh_work(self, name: str) -> float:
        """Cumulative work done by the spheres on the (moving) nodes of a mesh [J]:
        sum over steps of 1/2 (F_n + F_n+1) . v_node dt, plus F . dx for node jumps made by set_mesh_nodes."""
        return float(self._M.work[self._mesh(name)])

    def set_body_motion(self, name: str, kind: str, velocity=None, angular_velocity=None) -> None:
        """Prescribe the motion of a cluster: "free" (integrated), "fixed" (held still), "velocity" (moved with
        the given velocity and angular velocity, as LIGGGHTS fix move / YADE blockedDOFs). A prescribed body still
        feels its contacts (its reaction force is in the contacts table and in the body force); the work the
        prescription does enters the energy balance."""
        B = self.bodies
        names = B.names if B is not None else []
        if name not in names:
            raise ValueError(f"set_body_motion: no cluster named {name!r} (clusters: {', '.join(names) or 'none'})")
        if kind not in state.MOTION_KINDS:
            raise ValueError(f"set_body_motion({name!r}): kind must be one of free, fixed, velocity; got {kind!r}")
        b = names.index(name)
        vel = np.zeros(3) if velocity is None else np.asarray(velocity, float).reshape(3)
        spin = np.zeros(3) if angular_velocity is None else np.asarray(angular_velocity, float).reshape(3)
        if kind != "velocity" and (np.any(vel != 0.0) or np.any(spin != 0.0)):
            raise ValueError(f"set_body_motion({name!r}): velocity / angular_velocity only with kind 'velocity'")
        if self.planar and (vel[2] != 0.0 or spin[0] != 0.0 or spin[1] != 0.0):
            raise ValueError(f"set_body_motion({name!r}): a 2D scene allows vz = 0 and spin about z only")
        if not (np.isfinite(vel).all() and np.isfinite(spin).all()):
            raise ValueError(f"set_body_motion({name!r}): velocity and angular_velocity must be finite")
        P = self._B
        P.motion[b] = state.MOTION_KINDS[kind]
        P.vp[b] = vel
        P.wp[b] = spin
        self._motion_until[b] = math.inf
        if kind != "free":
            B.v[b] = vel
            B.w[b] = spin
            Rq = _quat_matrix(B.q[b])
            B.L[b] = Rq @ (B.Ip[b] * (Rq.T @ spin))
            cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, self.s.x, self.s.v, self.s.w)

    def set_time_step(self, dt: float) -> None:
        """Use time step dt from now on (before or between advances). ValueError above the stable limit."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"set_time_step: dt must be a positive number, got {dt!r}")
        if dt > self.dt_limit:
            raise ValueError(f"set_time_step: dt must be <= {self.dt_limit:.4g} s (stable limit: {self.dt_reason}), "
                             f"got {dt:g}")
        self.t0_time = self.time
        self._steps_since_dt = 0
        self.dt = dt

    def advance_to(self, t: float) -> None:
        """Advance to time t in steps of self.dt; SimulationError "solver time mismatch" when (t - time) / dt is not
        a non-negative integer within 1e-9 relative."""
        k = (float(t) - self.time) / self.dt
        n = round(k)
        if n < 0 or abs(k - n) > 1e-9 * max(1.0, abs(k)):
            raise SimulationError(self.nstep, self.time, "<all>", "solver time mismatch",
                                  f"advance_to({t!r}) from t = {self.time!r} is {k:.12g} steps of dt = {self.dt!r}, "
                                  "not a whole number (set_time_step to a divisor of the coupling step)")
        self.advance(int(n))

    def advance(self, nsteps: int) -> None:
        """Advance nsteps steps. While a gravity schedule runs, one step at a time with g(t_{n+1}) (the forces
        of velocity Verlet are evaluated at the end of the step); prescribed body motions end at their `until`."""
        M = self._M
        f_start = M.node_force.copy() if self.meshes else None
        M.node_acc[:] = 0.0
        total = nsteps
        while nsteps > 0 and self.time < self.gravity_until:
            self.gravity[:] = self.scene.gravity_at(self.time + self.dt)
            self._advance(1)
            nsteps -= 1
        while nsteps > 0:
            chunk = nsteps
            pending = self._motion_until > self.time
            if pending.any() and np.isfinite(self._motion_until[pending]).any():
                left = (self._motion_until[pending].min() - self.time) / self.dt
                chunk = max(1, min(chunk, int(math.ceil(left - 1e-9))))
            self._advance(chunk)
            nsteps -= chunk
            self._end_motions()
        if self.meshes and total > 0:
            self._node_avg = (0.5 * f_start + M.node_acc - 0.5 * M.node_force) / total

    def _end_motions(self) -> None:
        for b in np.nonzero((self._motion_until <= self.time + 1e-9 * self.dt))[0]:
            if self._B.motion[b] != state.FREE:
                self._B.motion[b] = state.FREE
            self._motion_until[b] = math.inf

    def _advance(self, nsteps: int) -> None:
        """Advance nsteps steps in the compiled step loop (advance.run_steps); Python only at neighbour-list
        rebuilds, after which the loop resumes the step it stopped in."""
        run = RUN_STEPS[bool(self.parallel)]
        done = 0
        resume = False
        while done < nsteps:
            k, stopped = run(nsteps - done, resume, self._S, self._W(), self._C(), self._B, self._M, self._P())
            done += k
            self.nstep += k
            self._steps_since_dt += k
            self.time = self.t0_time + self._steps_since_dt * self.dt
            resume = bool(stopped)
            if stopped:
                self._rebuild()

    def step(self) -> None:
        self.advance(1)

    def _advance_general(self, nsteps: int) -> None:
        """The same step driven one step at a time from Python (tests: identical to the fused loop)."""
        for _ in range(nsteps):
            self._advance(1)

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
        el = float(c.pstate[:, 3].sum() + c.wstate[:, 3].sum()) + self.mesh_elastic_energy()
        diss = float(self.diss.sum()) if self.track_energy else float("nan")
        return kin, pot, el, diss

    def work_input(self) -> float:
        """Work put into the spheres from outside since the start [J]: by the moving planes, by the moving mesh
        nodes (minus the work of the spheres on them) and by the prescription of body motions."""
        return float(self._wall_work[0] - self._M.work.sum() + self._B.work.sum())

    def mesh_elastic_energy(self) -> float:
        """Elastic energy stored in the sphere-mesh contacts (part of the energies() E_el column) [J]."""
        return float(self._M.slots[..., 6].sum()) if self.meshes else 0.0

    def mesh_drops(self) -> dict[str, dict[str, int]]:
        """Per mesh wall, what the contact pass could not handle since the start (sphere x force-evaluation counts):
        touching features beyond the per-sphere buffer (meshes.NFEAT), contacts beyond the history slots
        (meshes.KSLOT; their force was not applied) and contact rows beyond the output buffer."""
        keys = ("features_beyond_buffer", "contacts_beyond_slots", "rows_beyond_buffer")
        return {m.name: dict(zip(keys, (int(v) for v in self._M.drops[k]))) for k, m in enumerate(self.meshes)}

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


def run_dem(scene: Scene, out_dir: Path | None = None, progress: bool = True, restart: Restart | None = None,
            keep_tables: bool = True) -> Result:
    """Run a DEM-only scene to t_end and return the result tables. keep_tables = False (with out_dir): the body
    and contact rows are not held in memory; the returned StreamedResult reads them back from out_dir when used
    (coupler/results.py)."""
    from tqdm import tqdm
    t0 = time.perf_counter()
    ck = Checkpoints(restart, out_dir, scene)          # restart files (coupler/checkpoint.py)
    saved = ck.resumed()
    if saved is None:
        solver, elog, step = DEMSolver(scene), EnergyLog(), 0
    else:
        solver, elog, step = saved["solver"], saved["elog"], saved["step"]
    # this process's output rows the final tables are built from: body rows and times, contacts (t, i, j, data);
    # a resumed run's earlier rows stay on disk (bodies.csv, contacts.csv: Checkpoints.dem_tables), so a checkpoint
    # does not grow with them
    body_rows: list[np.ndarray] = []
    body_t: list[float] = []
    con_t: list[np.ndarray] = []
    con_i: list[str] = []
    con_j: list[str] = []
    con_d: list[np.ndarray] = []
    keep = keep_tables or out_dir is None
    dt = solver.dt
    n_steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    out = scene.output
    stream = None if out_dir is None else ResultStream(out_dir, ["bodies", "contacts", "energy"],
                                                       {"scene": scene.name, "backend": "native", "dt": dt,
                                                        "particles": solver.s.n},
                                                       resume=None if saved is None else (solver.time, 0))

    def record():
        solver.check_health()
        t = solver.time
        rows = {}
        if out.energy:
            k, p, e, d = solver.energies()
            elog.rows.append((t, k, p, e, d))
            _check_energy(solver, elog, k, p, e, d)
            rows["energy"] = elog.rows[-1:]
        if out.bodies:
            body = solver.body_table()
            rows["bodies"] = body_table([body], [t], solver.body_names())
            if keep:
                body_rows.append(body)
                body_t.append(t)
        if out.contacts:
            ii, jj, data = solver.contact_rows()
            tt = np.full(len(ii), t)
            rows["contacts"] = contact_table([tt], ii, jj, [data])
            if keep:
                con_i.extend(ii)
                con_j.extend(jj)
                con_d.append(data)
                con_t.append(tt)
        if stream is not None:            # after the checks: every table ends at the same good output time
            stream.append(t, rows)
        ck.output_done(t, step, lambda: {"solver": solver, "elog": elog, "step": step}, step == n_steps)

    try:
        if saved is None:
            record()
        bar = tqdm(total=n_steps, initial=step, disable=not progress, delay=3.0, unit="step", mininterval=1.0,
                   leave=False)
        while step < n_steps:
            chunk = min(every - (step % every), n_steps - step, HEALTH_EVERY)
            solver.advance(chunk)
            step += chunk
            bar.update(chunk)
            if step % every == 0 or step == n_steps:
                record()
            else:
                solver.check_health()
    except SimulationError as err:
        if stream is not None:
            stream.stopped(err)
        raise
    bar.close()
    wall = time.perf_counter() - t0

    energy = pd.DataFrame(elog.rows, columns=ENERGY_COLUMNS) if elog.rows else empty(ENERGY_COLUMNS)
    if keep:
        res = Result(energy=energy)
        ck.dem_tables(res, out, body_rows, body_t, solver.body_names(), (con_t, con_i, con_j, con_d))
    else:
        res = StreamedResult(out_dir, {}, energy)
    s = solver.s
    mem = solver.memory_bytes()
    res.summary = {
        "scene": scene.name, "backend": "native", "code_version": f"mpmdem {__version__}",
        "wall_time_s": wall, "steps": solver.nstep, "dt": dt, "particles": s.n,
        "dt_limit": solver.dt_limit, "dt_limit_reason": solver.dt_reason, "skin": solver.skin,
        "neighbour_rebuilds": solver.c.rebuilds, "memory_bytes": mem,
        "damping_beta": {f"{a}-{b}": float(solver.table[i, j, 2]) for i, a in enumerate(m.name for m in solver.materials)
                         for j, b in enumerate(m.name for m in solver.materials) if i <= j and np.isfinite(solver.table[i, j, 2])},
        "contact_law": {f"{k[0]}-{k[1]}": {"restitution": v.restitution, "friction": v.friction,
                                           "damping": v.damping, "tangential": v.tangential}
                        for k, v in scene.contacts.items()},
        "wall_effective_radius": "R (sphere radius), wall effective mass = sphere mass",
        **ck.summary(),
    }
    if solver.meshes:
        drops = solver.mesh_drops()
        res.summary["mesh_contacts_dropped"] = {**drops, "total": sum(sum(d.values()) for d in drops.values())}
    if solver.bodies is not None:
        res.summary["clusters"] = {
            "count": len(solver.bodies.names),
            "damping_effective_mass": scene.dem.cluster_damping_mass,
            "damping_effective_mass_meaning": ("body: m* uses the cluster mass (LIGGGHTS multisphere)"
                                               if scene.dem.cluster_damping_mass == "body" else
                                               "sphere: m* uses the member sphere mass (YADE clumps)"),
            "mass_property_error_max": float(solver.bodies.mass_error.max()),
        }
    if stream is not None:
        stream.finish(res)
        res.write(out_dir)
    return res


def _check_energy(solver: DEMSolver, elog: EnergyLog, k: float, p: float, e: float, d: float) -> None:
    """Energy jump detection: K + P + E_el + D minus the work put in from outside (moving planes and mesh nodes,
    prescribed bodies) may not grow by more than 10 % of the energy scale (E_el includes the mesh contacts)."""
    total = k + p + e + d
    w_in = solver.work_input()
    balance = total - w_in
    if elog.e0 is None:
        elog.e0 = balance
        elog.p0 = p
    elog.scale = max(elog.scale, k + e, elog.p0 - p, abs(w_in), 1e-300)
    if solver.time <= solver.gravity_until:     # gravity still changing: P is not a potential yet
        elog.e0 = None
        return
    if not math.isfinite(balance):
        return
    if balance - elog.e0 > 0.1 * elog.scale:
        raise SimulationError(solver.nstep, solver.time, "<all>", "total energy",
                              f"grew by {balance - elog.e0:.4g} J (scale {elog.scale:.4g} J"
                              + (f", work input of walls / prescribed bodies {w_in:.4g} J" if w_in else "")
                              + f"): unstable time step (dt = {solver.dt:.3g}, stable limit {solver.dt_limit:.3g}) "
                              "or bad input")


def _pack_meshes(meshes: list, n: int) -> state.Meshes:
    """All mesh walls in one set of arrays (per-mesh offsets); every Mesh keeps views into them (x, v,
    node_force, slots), so set_mesh_nodes and the tests see the arrays the kernels use."""
    nm = len(meshes)
    kv = meshes[0].faces.shape[1] if meshes else 3
    if any(m.faces.shape[1] != kv for m in meshes):
        raise ValueError("all mesh walls of a scene must have the same face kind (triangles or segments)")
    noff = np.zeros(nm + 1, np.int64)
    foff = np.zeros(nm + 1, np.int64)
    for k, m in enumerate(meshes):
        noff[k + 1] = noff[k] + len(m.x)
        foff[k + 1] = foff[k] + len(m.faces)
    X = np.zeros((noff[-1], 3))
    V = np.zeros((noff[-1], 3))
    NF = np.zeros((noff[-1], 3))
    faces = np.zeros((foff[-1], kv), np.int64)
    fe = np.zeros((foff[-1], 3), np.int64)
    slots = np.zeros((nm, n, msh.KSLOT, msh.SLOT))
    for k, m in enumerate(meshes):
        sl = slice(noff[k], noff[k + 1])
        X[sl], V[sl] = m.x, m.v
        faces[foff[k]:foff[k + 1]] = m.faces
        fe[foff[k]:foff[k + 1]] = m.face_edges
        m.x, m.v, m.node_force, m.slots = X[sl], V[sl], NF[sl], slots[k]
    return state.Meshes(x=X, v=V, x_ref=X.copy(), faces=faces, face_edges=fe, noff=noff, foff=foff,
                        mat=np.array([m.mat for m in meshes], np.int64), cand_off=np.zeros((nm, n + 1), np.int64),
                        cand=np.zeros(0, np.int64), cbase=np.zeros(nm + 1, np.int64), slots=slots, node_force=NF,
                        node_acc=np.zeros_like(NF), out=np.zeros((nm, 16, 7)), nout=np.zeros(nm, np.int64),
                        work=np.zeros(nm), drops=np.zeros((nm, 3), np.int64), moving=np.zeros(nm, np.bool_),
                        touched=np.zeros(noff[-1], np.int64), ntouched=np.zeros(nm, np.int64),
                        mark=np.zeros(noff[-1], np.bool_), ncon=np.zeros((nm, n), np.int64),
                        rec=np.zeros((0, 9)), recf=np.zeros(0, np.int64))


class FaceBins(NamedTuple):
    """One mesh's binned faces (meshes.bin_faces) and what they were built for: the nodes, the spheres' reach and
    their count."""
    nodes: np.ndarray
    reach: float
    n: int
    grid: tuple


def _mesh_candidates(M: state.Meshes, x: np.ndarray, r: np.ndarray, skin: float, bins: list,
                     parallel: bool = False) -> state.Meshes:
    """Candidate faces of every mesh (compiled binned search) and contact-row buffers sized for them. bins[k]:
    mesh k's binned faces with the nodes they were built from; kept while those nodes have not moved (a static
    mesh bins its faces once: 11 ms per build for 100,352 triangles), rebuilt otherwise."""
    nm = len(M.mat)
    lists = []
    cbase = np.zeros(nm + 1, np.int64)
    reach = msh.max_reach(r, skin)
    for k in range(nm):
        n0, n1, f0, f1 = M.noff[k], M.noff[k + 1], M.foff[k], M.foff[k + 1]
        b = bins[k]
        if b is None or b.reach != reach or b.n != len(x) or not np.array_equal(b.nodes, M.x[n0:n1]):
            b = bins[k] = FaceBins(M.x[n0:n1].copy(), reach, len(x),
                                   msh.bin_faces(M.x[n0:n1], M.faces[f0:f1], reach, len(x)))
        query = msh.query_faces_par if parallel else msh.query_faces_ser
        off, cand = query(x, r, skin, b.grid, M.x[n0:n1], M.faces[f0:f1])
        M.cand_off[k] = off
        lists.append(cand)
        cbase[k + 1] = cbase[k] + len(cand)
    cap = max([16] + [4 * len(c) for c in lists])
    M.x_ref[:] = M.x
    cand = np.concatenate(lists) if lists else np.zeros(0, np.int64)
    return M._replace(cand=cand, cbase=cbase, out=np.zeros((nm, cap, 7)), rec=np.zeros((len(cand), 9)),
                      recf=np.zeros(len(cand), np.int64))


def _pack_bodies(B) -> state.Bodies:
    if B is None:
        z3 = np.zeros((0, 3))
        return state.Bodies(c=z3, q=np.zeros((0, 4)), v=z3, L=z3, w=z3, mass=np.zeros(0), Ip=z3, F=z3, T=z3,
                            member=np.zeros(0, np.int64), owner=np.zeros(0, np.int64), offset=z3,
                            qtmp=np.zeros((0, 4)), wtmp=z3, motion=np.zeros(0, np.int8), vp=z3, wp=z3,
                            work=np.zeros(0))
    nb = len(B.names)
    return state.Bodies(c=B.c, q=B.q, v=B.v, L=B.L, w=B.w, mass=B.mass, Ip=B.Ip, F=B.F, T=B.T, member=B.member,
                        owner=B.owner, offset=B.offset, qtmp=B.q.copy(), wtmp=B.w.copy(),
                        motion=np.zeros(nb, np.int8), vp=np.zeros((nb, 3)), wp=np.zeros((nb, 3)), work=np.zeros(nb))


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
