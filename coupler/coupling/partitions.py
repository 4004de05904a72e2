"""Partitions: the native DEM and MPM solvers behind the coupling contract (COORD.md, design.md).

This module is the ONLY place in coupler/coupling that knows DEMSolver / MPMSolver. Until the contract methods land
on the solvers (dem-step: set_time_step, advance_to, time-averaged mesh_node_forces, mesh_work, set_body_motion,
rebuild on actual node displacement; mpm: advance_to, set_point_loads, interface_state, dropped_loads) the same
methods are implemented here on the current solvers; every such stop-gap is marked STOP-GAP with what replaces it.

DEM partition contract:  time, dt, advance_to(t), set_interface(x, v), interface_forces(), interface_work(),
                         energies(), momentum(), tables
MPM partition contract:  time, dt, advance_to(t), set_point_loads(f), interface_state(), energies(), momentum(),
                         tables
"""
from __future__ import annotations

import math

import numpy as np

from coupler.errors import SceneError, SimulationError


class DEMPartition:
    def __init__(self, scene, wall_name: str, dt: float, motions=()):
        from coupler.dem.solver import DEMSolver
        self.sol = DEMSolver(scene)
        self.wall_name = wall_name
        if dt > self.sol.dt_limit * (1 + 1e-12):
            raise SceneError("coupling.dem_substeps", f"DEM step {dt:.4g} s exceeds the DEM stable limit "
                                                      f"{self.sol.dt_limit:.4g} s ({self.sol.dt_reason}); raise it")
        # STOP-GAP (dem-step: DEMSolver.set_time_step(dt)): the step is set before the first advance
        self.sol.dt = float(dt)
        self.mesh = next(m for m in self.sol.meshes if m.name == wall_name)
        self._f_avg = np.zeros((len(self.mesh.x), 3))
        self._work = 0.0
        # STOP-GAP (dem-step: [[dem.clusters]] motion / DEMSolver.set_body_motion): held or driven clusters
        names = self.sol.bodies.names if self.sol.bodies is not None else []
        self.motions = [(names.index(m.body), m) for m in motions]
        self.hold_force = {m.body: np.zeros(3) for m in motions}
        self._now = []
        self._x_ref = self.mesh.x.copy()          # node positions at the last neighbour build (stop-gap)
        self._nbuild = self.sol.c.rebuilds

    # -- contract -----------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.sol.time

    @property
    def dt(self) -> float:
        return self.sol.dt

    def set_interface(self, x: np.ndarray, v: np.ndarray) -> None:
        """Wall node positions now and their velocities over the coupling step, (nn, 2)."""
        nn = len(self.mesh.x)
        x3 = np.zeros((nn, 3))
        v3 = np.zeros((nn, 3))
        x3[:, :2], v3[:, :2] = x, v
        self.sol.set_mesh_nodes(self.wall_name, x3, v3)
        # STOP-GAP (dem-step: rebuild on the actual node displacement since the last build): the solver's rebuild
        # test adds wall_speed x (time since the last build) to the sphere displacement, with a wall speed fixed at
        # construction. Here: rebuild now if the node jump since the last build plus the sphere displacement
        # reaches skin/2; otherwise set wall_speed so that wall_speed (t' - t_ref) bounds the node displacement
        # at every t' of the coming step: |jump| (t' - t_ref)/(t - t_ref) + |v| (t' - t_ref) >= |jump| + |v|(t' - t).
        from coupler.dem.advance import _max_disp_sq
        sol, c = self.sol, self.sol.c
        jump = float(np.sqrt(((x3 - self._x_ref) ** 2).sum(1)).max()) if nn else 0.0
        vmax = float(np.sqrt((v3 ** 2).sum(1)).max()) if nn else 0.0
        sol.walls_move = True
        if jump + math.sqrt(_max_disp_sq(sol.s.x, c.x_ref)) > 0.5 * sol.skin:
            self._rebuild()
            sol.wall_speed = vmax
        else:
            since = sol.time - c.t_ref
            sol.wall_speed = vmax + (jump / since if since > 0 else 0.0)

    def _rebuild(self) -> None:
        self.sol._rebuild()
        self._x_ref = self.mesh.x.copy()
        self._nbuild = self.sol.c.rebuilds

    def advance_to(self, t: float) -> None:
        """Steps of dt to t; node forces time-averaged as velocity Verlet delivers the impulse (trapezoid)."""
        sol = self.sol
        r = (t - sol.time) / sol.dt
        n = int(round(r))
        if n < 1 or abs(r - n) > 1e-9 * max(1.0, r):
            raise SimulationError(sol.nstep, sol.time, "<dem>", "time",
                                  f"solver time mismatch: ({t:.12g} - {sol.time:.12g}) / dt = {r:.12g} is not a "
                                  f"positive integer")
        # STOP-GAP (dem-step: advance_to(t) + time-averaged mesh_node_forces + mesh_work in compiled code)
        m = self.mesh
        acc = 0.5 * m.node_force          # force of the step before: its second half kick is in this interval
        work = 0.0
        vnode = m.v.copy()
        for k in range(n):
            self._hold_before()
            sol.advance(1)
            self._hold_after()
            if sol.c.rebuilds != self._nbuild:    # the solver rebuilt inside the step (at these node positions)
                self._x_ref = m.x.copy()
                self._nbuild = sol.c.rebuilds
            w = 0.5 if k == n - 1 else 1.0
            acc = acc + w * m.node_force
        impulse = acc * sol.dt
        self._f_avg = impulse / (n * sol.dt)
        self._work += float(np.sum(impulse * vnode))     # node velocities constant over the coupling step
        sol.check_health()

    def interface_forces(self) -> np.ndarray:
        """Time-averaged force BY the spheres ON the wall nodes over the last advance_to, (nn, 2) [N]."""
        return self._f_avg[:, :2].copy()

    def interface_work(self) -> float:
        """Cumulative work done by the spheres on the moving wall nodes [J]."""
        return self._work

    # -- prescribed motion (STOP-GAP, see __init__) --------------------------------------------------------------
    def _active(self):
        """The motion entries active over the coming step (chosen at its start time)."""
        t = self.sol.time
        return [(b, m) for b, m in self.motions if m.start <= t + 1e-12 * max(1.0, t) < m.until]

    def _hold_before(self) -> None:
        B = self.sol.bodies
        self._now = self._active()
        for b, m in self._now:
            self.hold_force[m.body] = B.F[b].copy()
            B.F[b] = 0.0          # first half kick adds nothing: the drift moves the body with the prescribed v
            B.T[b] = 0.0
            B.v[b] = m.velocity if m.kind == "velocity" else 0.0
            B.L[b] = 0.0
            B.w[b] = 0.0

    def _hold_after(self) -> None:
        B = self.sol.bodies
        if not self._now:
            return
        from coupler.dem import clusters as cl
        for b, m in self._now:
            B.v[b] = m.velocity if m.kind == "velocity" else 0.0
            B.L[b] = 0.0
            B.w[b] = 0.0
        s = self.sol.s
        cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, s.x, s.v, s.w)

    # -- diagnostics --------------------------------------------------------------------------------------------
    def energies(self) -> tuple[float, float, float, float]:
        """(kinetic, potential, elastic, dissipated) [J]; elastic includes the sphere-mesh contacts."""
        k, p, e, d = self.sol.energies()
        # STOP-GAP (dem-step): DEMSolver.energies() leaves out the elastic energy stored in mesh contact slots
        for mm in self.sol.meshes:
            act = mm.slots[:, :, 10] != 0.0
            e += float(mm.slots[:, :, 6][act].sum())
        return k, p, e, d

    def momentum(self) -> np.ndarray:
        s = self.sol.s
        free = s.body < 0
        p = (s.mass[free, None] * s.v[free]).sum(0)
        if self.sol.bodies is not None:
            B = self.sol.bodies
            p = p + (B.mass[:, None] * B.v).sum(0)
        return p

    def body_mass(self, name: str) -> float:
        B = self.sol.bodies
        if B is not None and name in B.names:
            return float(B.mass[B.names.index(name)])
        s = self.sol.s
        return float(s.mass[s.names.index(name)])

    def total_mass(self) -> float:
        s = self.sol.s
        m = float(s.mass[s.body < 0].sum())
        return m + (float(self.sol.bodies.mass.sum()) if self.sol.bodies is not None else 0.0)

    def body_names(self) -> list[str]:
        return self.sol.body_names()

    def body_table(self) -> np.ndarray:
        return self.sol.body_table()

    def contact_rows(self):
        return self.sol.contact_rows()

    def n_spheres(self) -> int:
        return int(self.sol.s.n)

    def info(self) -> dict:
        return {"dem_dt": self.sol.dt, "dem_dt_limit": self.sol.dt_limit, "dem_dt_limit_reason": self.sol.dt_reason,
                "dem_neighbour_rebuilds": self.sol.c.rebuilds, "dem_steps": self.sol.nstep}


class MPMPartition:
    def __init__(self, scene, dt: float | None):
        from coupler.mpm.solver import MPMSolver
        self.sol = MPMSolver(scene)
        cmax = self.sol.dt / scene.mpm.cfl           # dt = cfl h / c: the cfl = 1 limit
        if dt is not None:
            if dt > cmax * (1 + 1e-12):
                raise SceneError("coupling.dt", f"must be <= the MPM CFL limit cell_size / wave speed = {cmax:.4g} s "
                                                f"(cfl = 1), got {dt:g}")
            # STOP-GAP (mpm: advance_to(t) takes equal steps <= dt): the MPM step is set to the coupling step
            self.sol.dt = float(dt)
        self.nb = len(self.sol.xb)
        self._loads = np.zeros((self.nb, 2))

    @property
    def time(self) -> float:
        return self.sol.t

    @property
    def dt(self) -> float:
        return self.sol.dt

    def advance_to(self, t: float) -> None:
        # STOP-GAP (mpm: MPMSolver.advance_to(t) in compiled code): k equal steps of (t - now)/k <= dt
        sol = self.sol
        k = int(math.ceil((t - sol.t) / sol.dt - 1e-9))
        if k < 1:
            raise SimulationError(sol.nstep, sol.t, "<mpm>", "time", f"solver time mismatch: target {t:.12g}")
        dt0 = sol.dt
        sol.dt = (t - sol.t) / k
        for _ in range(k):
            sol.step()
        sol.dt = dt0
        sol.t = t

    def set_point_loads(self, f: np.ndarray) -> None:
        """(nb, 2) N per unit depth on the boundary particles, held until changed."""
        self._loads = np.asarray(f, float).copy()
        # STOP-GAP (mpm: set_point_loads; apply_point_loads stays as an alias)
        self.sol.apply_point_loads(self._loads)

    def interface_state(self) -> dict:
        # STOP-GAP (mpm: interface_state(); boundary_particle_state stays)
        return self.sol.boundary_particle_state()

    def energies(self) -> dict:
        """kinetic, potential, elastic per unit depth [J/m]."""
        return self.sol.energies()

    def momentum(self) -> np.ndarray:
        """Linear momentum per unit depth [N s / m]."""
        return (self.sol.m[:, None] * self.sol.v).sum(0)

    def particles_frame(self):
        return self.sol.particles_frame()

    def body_rows(self):
        return self.sol.body_rows()

    def n_points(self) -> int:
        return int(len(self.sol.m))

    def info(self) -> dict:
        return {"mpm_dt": self.sol.dt, "mpm_steps": self.sol.nstep, "mpm_points": self.n_points(),
                "mpm_boundary_particles": self.nb, "mpm_cells": [self.sol.nx, self.sol.ny]}

    @staticmethod
    def write_vtk(result, out) -> None:
        from coupler.mpm.solver import _write_vtu
        _write_vtu(result, out)
