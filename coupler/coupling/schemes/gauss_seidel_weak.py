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


class GaussSeidelWeak:
    def __init__(self, dem, mpm, mapper, index: np.ndarray, wall_x0: np.ndarray, thickness: float):
        self.dem, self.mpm, self.mapper = dem, mpm, mapper
        self.index = index
        # a contiguous run of boundary particles: read and write through a slice (views, no gathers)
        i = np.asarray(index)
        if len(i) and np.array_equal(i, np.arange(i[0], i[0] + len(i))):
            self.index = slice(int(i[0]), int(i[0]) + len(i))
        self._loads = np.zeros((mpm.nb, 2))
        self._d0 = None          # MPM dropped-load counters after the last step
        self.wall_x0 = wall_x0
        self.thickness = thickness
        self.work_mpm = 0.0
        self.timers = {"dem": 0.0, "mpm": 0.0, "map": 0.0, "interface": 0.0, "exchange": 0.0}
        self.last = {}
        self.dropped_steps = 0   # coupling steps in which part of the point load was dropped by the MPM
        self._state = None       # MPM interface state at the end of the last step (= the start of this one)

    def step(self, t: float, dt: float) -> None:
        T = self.timers
        c0 = time.perf_counter()
        st = self._state if self._state is not None else self.mpm.interface_state()
        u = st["displacement"][self.index]
        v = st["velocity"][self.index]
        x_before = st["x"][self.index]
        c1 = time.perf_counter()
        kin = self.mapper.kinematics(np.hstack([u, v]))   # one gather for both fields
        xw = self.wall_x0 + kin[:, :2]
        vw = kin[:, 2:]
        c2 = time.perf_counter()
        self.dem.set_interface(xw, vw)
        c3 = time.perf_counter()
        self.dem.advance_to(t + dt)
        c4 = time.perf_counter()
        F = self.dem.interface_forces()                  # N, by the spheres on the wall nodes
        c5 = time.perf_counter()
        fb = self.mapper.forces(F) / self.thickness      # N per unit depth on the interface particles
        c6 = time.perf_counter()
        loads = self._loads            # zero outside the interface; set_point_loads copies it
        loads[self.index] = fb
        self.mpm.set_point_loads(loads)
        c7 = time.perf_counter()
        d0 = self._d0 if self._d0 is not None else self.mpm.dropped_loads()
        self.mpm.advance_to(t + dt)
        c8 = time.perf_counter()
        d1 = self._d0 = self.mpm.dropped_loads()
        keep = 1.0
        if d1["impulse_dropped"] > d0["impulse_dropped"]:
            # loads whose support held no grid mass never reached the MPM; the solver counts |f| dt only, so the
            # received resultant is the applied one scaled by the kept fraction of this step (exact when nothing
            # is dropped; an estimate otherwise, counted in dropped_steps)
            keep = 1.0 - (d1["impulse_dropped"] - d0["impulse_dropped"]) / (d1["impulse_applied"]
                                                                           - d0["impulse_applied"])
            self.dropped_steps += 1
        self._state = self.mpm.interface_state()
        x_after = self._state["x"][self.index]
        self.work_mpm += keep * self.thickness * float(np.sum(fb * (x_after - x_before)))
        c9 = time.perf_counter()
        T["exchange"] += (c1 - c0) + (c5 - c4) + (c7 - c6) + (c9 - c8)
        T["map"] += (c2 - c1) + (c6 - c5)
        T["interface"] += c3 - c2
        T["dem"] += c4 - c3
        T["mpm"] += c8 - c7
        self.last_loads = fb
        self.last = {"fx_dem": float(F[:, 0].sum()), "fy_dem": float(F[:, 1].sum()),
                     "fx_mpm": keep * float(fb[:, 0].sum() * self.thickness),
                     "fy_mpm": keep * float(fb[:, 1].sum() * self.thickness),
                     "work_dem": self.dem.interface_work(), "work_mpm": self.work_mpm}
