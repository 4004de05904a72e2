"""Weak (explicit, one pass) Gauss-Seidel coupling, DEM solved first (Kratos CoSimulation `gauss_seidel_weak`).

One coupling step t -> t + dt:
  1. wall nodes <- map_kin(MPM interface displacement, velocity at t); the DEM advances to t + dt with its own
     step (n sub-steps), the nodes moving linearly x(t') = x(t) + v (t' - t);
  2. f_mpm = map_force(time-averaged wall node forces) / thickness   [N per unit depth];
  3. the MPM advances to t + dt with f_mpm as point loads on the interface particles;
  4. (next step) the new MPM interface kinematics go to the wall.
The impulse the DEM spheres receive from the wall in the step equals the impulse the MPM receives (x thickness),
so linear momentum is exchanged exactly; the interface work of the two sides differs by the staggering
(work_dem - work_mpm in interface.csv).
"""
from __future__ import annotations

import time

import numpy as np

from coupler.coupling.schemes.predictors import PREDICTORS  # the wall-velocity predictors (docstring there)


class GaussSeidelWeak:
    def __init__(self, dem, mpm, mapper, index: np.ndarray, wall_x0: np.ndarray, thickness: float,
                 predictor: str = "constant"):
        self.dem, self.mpm, self.mapper = dem, mpm, mapper
        if predictor not in PREDICTORS:
            raise ValueError(f"predictor must be one of {', '.join(PREDICTORS)}, got {predictor!r}")
        self.predictor = predictor
        self._v_prev = None      # MPM interface velocity one step further back (the linear predictor)
        self.index = index
        # a contiguous run of boundary particles: read and write through a slice (views, no gathers)
        i = np.asarray(index)
        if len(i) and np.array_equal(i, np.arange(i[0], i[0] + len(i))):
            self.index = slice(int(i[0]), int(i[0]) + len(i))
        self._drop = None        # MPM dropped-load impulse counters after the last step
        self.wall_x0 = wall_x0
        self.thickness = thickness
        self.work_mpm = 0.0
        self.timers = {"dem": 0.0, "mpm": 0.0, "map": 0.0, "interface": 0.0, "exchange": 0.0}
        self.clock = time.perf_counter   # the timers' clock (the bench may use time.thread_time: CPU time)
        self.last = {}
        self.dropped_steps = 0   # coupling steps in which part of the point load was dropped by the MPM
        self._state = None       # MPM interface (x, u, v) at the end of the last step (= the start of this one)

    def step(self, t: float, dt: float) -> None:
        T, clock = self.timers, self.clock
        mpm, dem, mapper, idx = self.mpm, self.dem, self.mapper, self.index
        c0 = clock()
        if self._state is None:
            self._state = mpm.interface_kinematics(idx)
            self._drop = mpm.dropped_impulse()
        x_before, u, v = self._state          # MPM interface kinematics at the end of the last step
        c1 = clock()
        xw = self.wall_x0 + mapper.kinematics(u)
        if self.predictor == "linear" and self._v_prev is not None:
            vw = mapper.kinematics(2.0 * v - self._v_prev)     # the velocity of this step, extrapolated
        else:
            vw = mapper.kinematics(v)
        self._v_prev = v
        c2 = clock()
        dem.set_interface(xw, vw)
        c3 = clock()
        dem.advance_to(t + dt)
        c4 = clock()
        F = dem.interface_forces()                  # N, by the spheres on the wall nodes
        c5 = clock()
        fb = mapper.forces(F) / self.thickness      # N per unit depth on the interface particles
        c6 = clock()
        mpm.set_interface_loads(idx, fb)
        c7 = clock()
        mpm.advance_to(t + dt)
        c8 = clock()
        d0, a0 = self._drop
        d1, a1 = self._drop = mpm.dropped_impulse()
        keep = 1.0
        if d1 > d0:
            # loads whose support held no grid mass never reached the MPM; the solver counts |f| dt only, so the
            # received resultant is the applied one scaled by the kept fraction of this step (exact when nothing
            # is dropped; an estimate otherwise, counted in dropped_steps)
            keep = 1.0 - (d1 - d0) / (a1 - a0)
            self.dropped_steps += 1
        self._state = x_after, _, _ = mpm.interface_kinematics(idx)
        self.work_mpm += keep * self.thickness * float(np.sum(fb * (x_after - x_before)))
        self.last_loads = fb
        th = self.thickness
        self.last = {"fx_dem": float(F[:, 0].sum()), "fy_dem": float(F[:, 1].sum()),
                     "fx_mpm": keep * float(fb[:, 0].sum() * th), "fy_mpm": keep * float(fb[:, 1].sum() * th),
                     "work_dem": dem.interface_work(), "work_mpm": self.work_mpm}
        c9 = clock()
        T["exchange"] += (c1 - c0) + (c5 - c4) + (c7 - c6) + (c9 - c8)
        T["map"] += (c2 - c1) + (c6 - c5)
        T["interface"] += c3 - c2
        T["dem"] += c4 - c3
        T["mpm"] += c8 - c7
