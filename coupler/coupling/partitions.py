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
import math

import numpy as np

from coupler.coupling.exchange import set_wall
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
        # set_interface in compiled code (coupling/exchange.set_wall: DEMSolver.set_mesh_nodes' arithmetic on the
        # solver's node arrays, the same bits)
        self._k = next(k for k, m in enumerate(self.sol.meshes) if m is self.mesh)
        self._shape = (len(self.mesh.x), 2)
        self._scratch = np.zeros(3 * len(self.mesh.x))
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
        m = self.mesh
        if x.shape != self._shape or v.shape != self._shape or not set_wall(x, v, m.x, m.v, m.node_force,
                                                                            self.sol._M.work, self._k, self._scratch):
            self._x3[:, :2] = x            # the solver's own checks and errors (shape, finite)
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
        if dt is not None:
            # the explicit step's stability bound, dt = cfl h / c at cfl = 1 (the implicit Newmark step has none:
            # a step that does not converge is cut; before the thirty-fifth session the implicit step was held to
            # [mpm.implicit] cfl / mpm.cfl x h / c, 10 h / c by default, with this message)
            cmax = self.sol.dt / scene.mpm.cfl if scene.mpm.scheme == "explicit" else math.inf
            if dt > cmax * (1 + 1e-12):
                raise SceneError("coupling.dt", f"must be <= the MPM CFL limit cell_size / wave speed = {cmax:.4g} s "
                                                f"(cfl = 1), got {dt:g}")
            self.sol.dt = float(dt)        # the MPM step is the coupling step (advance_to then takes one step)
        self.nb = len(self.sol.interface_state()["x"])

    def checkpoint_refusal(self) -> str | None:
        """Why a run checkpoint cannot hold this partition (coupler/checkpoint.py; None: it can)."""
        return self.sol.checkpoint_refusal()

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

    def boundary_arrays(self) -> tuple[np.ndarray, ...]:
        """The solver's own boundary-particle arrays, read and written in place by the scheme's compiled exchange
        (coupling/exchange.py): x, x0 (start positions), v (nb, 2), point loads f (nb, 2, held until changed) and
        the dropped-load counters (count, impulse dropped, impulse applied, max fraction; see dropped_loads)."""
        s = self.sol
        return s.xb, s.xb0, s.vb, s.fb, s.drop

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
                "mpm_dropped_loads": self.dropped_loads(),
                "mpm_stranded_boundary_particles": self.sol.stranded_boundary_particles(),
                **getattr(self.sol, "scheme_summary", dict)()}

