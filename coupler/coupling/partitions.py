"""Partitions: the native DEM and MPM solvers behind the coupling contract (COORD.md, design.md).

This module is the ONLY place in coupler/coupling that knows DEMSolver / MPMSolver. It wraps them through their
step contracts only: DEM set_time_step, advance_to, set_mesh_nodes (the solver rebuilds on the actual node
displacement), mesh_node_forces (time-averaged over the last advance), mesh_work, set_body_motion, energies +
mesh_elastic_energy; MPM advance_to, set_point_loads, interface_state, dropped_loads.

DEM partition contract:  time, dt, advance_to(t), set_interface(x, v), interface_forces(), interface_work(),
                         energies(), momentum(), tables
MPM partition contract:  time, dt, advance_to(t), set_point_loads(f), interface_state(), dropped_loads(),
                         energies(), momentum(), tables
"""
from __future__ import annotations

import importlib

import numpy as np

from coupler.errors import SceneError

# `[coupling] dem_partition`: the classes implementing the DEM partition contract, by module name (resolved with
# importlib when a run asks for one, like coupler/run.py BACKENDS: coupler never imports adapters at module level)
DEM_PARTITIONS: dict[str, str] = {"native": "coupler.coupling.partitions:DEMPartition",
                                  "yade": "adapters.yade.partition:YadeDEMPartition"}


def dem_partition_class(name: str):
    """The class of a registered DEM partition (SceneError naming the field for an unknown name)."""
    if name not in DEM_PARTITIONS:
        raise SceneError("coupling.dem_partition", f"must be one of {', '.join(map(repr, DEM_PARTITIONS))}; "
                                                   f"got {name!r}")
    module, _, cls = DEM_PARTITIONS[name].partition(":")
    return getattr(importlib.import_module(module), cls)


class DEMPartition:
    def __init__(self, scene, wall_name: str, dt: float, motions=()):
        from coupler.dem.solver import DEMSolver
        self.sol = DEMSolver(scene)
        self.wall_name = wall_name
        try:
            self.sol.set_time_step(dt)
        except ValueError as e:
            raise SceneError("coupling.dem_substeps", f"DEM step {dt:.4g} s: {e}; raise dem_substeps") from None
        self.mesh = next(m for m in self.sol.meshes if m.name == wall_name)
        self._x3 = np.zeros((len(self.mesh.x), 3))        # z stays 0 (2D)
        self._v3 = np.zeros((len(self.mesh.x), 3))
        # motion schedules ([[coupling.motion]], several phases per cluster; a single phase is [[dem.clusters]]
        # motion, handled by the solver itself): each phase is set through DEMSolver.set_body_motion at the start
        # of the coupling step it begins in; outside the phases the cluster is free
        self.motions = list(motions)
        self._phase = {m.body: None for m in self.motions}

    # -- contract -----------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.sol.time

    @property
    def dt(self) -> float:
        return self.sol.dt

    def set_interface(self, x: np.ndarray, v: np.ndarray) -> None:
        """Wall node positions now and their velocities over the coupling step, (nn, 2). The solver rebuilds its
        neighbour lists on the actual node displacement since the last build."""
        self._x3[:, :2] = x                # the solver copies them into its own node arrays
        self._v3[:, :2] = v
        self.sol.set_mesh_nodes(self.wall_name, self._x3, self._v3)

    def advance_to(self, t: float) -> None:
        """Steps of dt to t ("solver time mismatch" otherwise); node forces time-averaged by the solver."""
        if self.motions:
            self._apply_motions()
        self.sol.advance_to(t)
        self.sol.check_health()

    def interface_forces(self) -> np.ndarray:
        """Time-averaged force BY the spheres ON the wall nodes over the last advance_to, (nn, 2) [N]."""
        return self.sol.mesh_node_forces(self.wall_name)[:, :2]

    def interface_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Wall node positions now and the node velocities of the current coupling step, (nn, 2) each (an
        addition to the COORD.md partition contract; output only)."""
        return self.mesh.x[:, :2].copy(), self.mesh.v[:, :2].copy()

    def interface_work(self) -> float:
        """Cumulative work done by the spheres on the moving wall nodes [J] (node drift and node jumps)."""
        return self.sol.mesh_work(self.wall_name)

    # -- motion schedules --------------------------------------------------------------------------------------
    def _apply_motions(self) -> None:
        t = self.sol.time
        eps = 1e-9 * self.sol.dt
        for body in self._phase:
            now = next((m for m in self.motions if m.body == body and m.start - eps <= t < m.until - eps), None)
            if now is not self._phase[body]:
                if now is None:
                    self.sol.set_body_motion(body, "free")
                else:
                    self.sol.set_body_motion(body, now.kind, now.velocity if now.kind == "velocity" else None)
                self._phase[body] = now

    # -- diagnostics --------------------------------------------------------------------------------------------
    def energies(self) -> tuple[float, float, float, float]:
        """(kinetic, potential, elastic, dissipated) [J]; elastic includes the sphere-mesh contacts."""
        return self.sol.energies()          # E_el includes the sphere-mesh contacts (DEMSolver.energies, issue 17)

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

    def close(self) -> None:
        """Nothing to release in-process (the contract's close(): the YADE partition ends its process)."""

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
            self.sol.dt = float(dt)        # the MPM step is the coupling step (advance_to then takes one step)
        self.nb = len(self.sol.interface_state()["x"])
        # MPMSolver's boundary-particle arrays, read and written in place by the per-step fast path (another MPM
        # solver behind this partition, e.g. the implicit one, goes through its interface_state contract)
        self._fast = all(hasattr(self.sol, a) for a in ("xb", "xb0", "vb", "fb", "drop"))

    @property
    def time(self) -> float:
        return self.sol.t

    @property
    def dt(self) -> float:
        return self.sol.dt

    def advance_to(self, t: float) -> None:
        """k = ceil((t - now)/dt) equal steps <= dt to t (one step per coupling step: dt is the coupling step)."""
        self.sol.advance_to(t)

    def set_point_loads(self, f: np.ndarray) -> None:
        """(nb, 2) N per unit depth on the boundary particles, held until changed."""
        self.sol.set_point_loads(f)

    def interface_state(self) -> dict:
        return self.sol.interface_state()

    def dropped_loads(self) -> dict:
        """count, impulse_dropped, impulse_applied [N s per unit depth, sums of |f| dt], max_fraction, limit."""
        return self.sol.dropped_loads()

    # -- the per-step fast path of the scheme (the same values as interface_state / set_point_loads /
    #    dropped_loads, without building dicts and copying every boundary-particle array each step) ------------
    def interface_kinematics(self, index) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, displacement, velocity) of the boundary particles `index` (a slice or an index array), (ni, 2)
        each, fresh arrays (a solver without the arrays xb, xb0, vb goes through interface_state)."""
        s = self.sol
        if self._fast:
            x = s.xb[index]
            return (x.copy() if isinstance(index, slice) else x), s.xb[index] - s.xb0[index], s.vb[index].copy()
        st = s.interface_state()
        return st["x"][index], st["displacement"][index], st["velocity"][index]

    def set_interface_loads(self, index, f: np.ndarray) -> None:
        """Point loads (ni, 2) [N per unit depth] on the boundary particles `index`, zero on all others (the
        scheme's only loads), held until changed."""
        if self._fast:
            if not np.isfinite(f).all():
                raise ValueError("point loads must be finite")
            self.sol.fb[index] = f
            return
        loads = np.zeros((self.nb, 2))
        loads[index] = f
        self.sol.set_point_loads(loads)

    def dropped_impulse(self) -> tuple[float, float]:
        """(impulse_dropped, impulse_applied) so far [N s per unit depth], as dropped_loads()."""
        if self._fast:
            d = self.sol.drop
            return float(d[1]), float(d[2])
        d = self.sol.dropped_loads()
        return d["impulse_dropped"], d["impulse_applied"]

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
                "mpm_boundary_particles": self.nb, "mpm_cells": [self.sol.nx, self.sol.ny],
                "mpm_dropped_loads": self.dropped_loads(), **getattr(self.sol, "scheme_summary", dict)()}

    @staticmethod
    def write_vtk(result, out) -> None:
        from coupler.mpm.solver import _write_vtu
        _write_vtu(result, out)
