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

from coupler.coupling import exchange
from coupler.coupling.schemes.predictors import PREDICTORS  # the wall-velocity predictors (docstring there)


class GaussSeidelWeak:
    def __init__(self, dem, mpm, mapper, index: np.ndarray, wall_x0: np.ndarray, thickness: float,
                 predictor: str = "constant"):
        self.dem, self.mpm, self.mapper = dem, mpm, mapper
        if predictor not in PREDICTORS:
            raise ValueError(f"predictor must be one of {', '.join(PREDICTORS)}, got {predictor!r}")
        self.predictor = predictor
        self.index = np.ascontiguousarray(index, np.int64)
        self.wall_x0 = np.ascontiguousarray(wall_x0, float)
        self.thickness = float(thickness)
        self.timers = {"dem": 0.0, "mpm": 0.0, "map": 0.0, "interface": 0.0, "exchange": 0.0}
        self.clock = time.perf_counter   # the timers' clock (the bench may use time.thread_time: CPU time)
        self.dropped_steps = 0   # coupling steps in which part of the point load was dropped by the MPM
        self.last_loads = None   # the point loads of the last step, (ni, 2) [N per unit depth]
        # preallocated work arrays of the compiled exchange (coupling/exchange.py): no allocation per step
        ni, nn = len(self.index), len(self.wall_x0)
        self._u, self._vin, self._v_prev, self._x_before, self._fb = (np.zeros((ni, 2)) for _ in range(5))
        self._xw, self._vw = np.zeros((nn, 2)), np.zeros((nn, 2))
        self._scratch = np.zeros(2 * ni)
        self._drop_prev = np.zeros(2)       # MPM dropped / applied load impulse after the last step
        self._started = False
        # t, fx_dem, fy_dem, fx_mpm, fy_mpm, work_dem, work_mpm of the last step (INTERFACE_COLUMNS; t is the run's)
        self.row = np.zeros(7)

    @property
    def work_mpm(self) -> float:
        return float(self.row[6])

    @property
    def last(self) -> dict:
        """The interface.csv values of the last step (without t), as floats."""
        return dict(zip(("fx_dem", "fy_dem", "fx_mpm", "fy_mpm", "work_dem", "work_mpm"), self.row[1:].tolist()))

    def step(self, t: float, dt: float) -> None:
        T, clock = self.timers, self.clock
        dem, mapper, idx = self.dem, self.mapper, self.index
        c0 = clock()
        xb, xb0, vb, fb, drop = self.mpm.boundary_arrays()     # the MPM solver's live arrays
        if not self._started:
            self._drop_prev[:] = drop[1:3]
        c1 = clock()
        exchange.wall_kinematics(xb, xb0, vb, idx, mapper.cols, mapper.w, mapper.identity, self.wall_x0,
                                 self.predictor == "linear", self._v_prev, self._started, self._u, self._vin,
                                 self._xw, self._vw, self._x_before)
        self._started = True
        c2 = clock()
        dem.set_interface(self._xw, self._vw)
        c3 = clock()
        dem.advance_to(t + dt)
        c4 = clock()
        F = dem.interface_forces()                  # N, by the spheres on the wall nodes
        c5 = clock()
        if not exchange.point_loads(F, mapper._c, mapper._w, mapper.identity, self.thickness, self._fb, fb, idx,
                                    self.row):
            raise ValueError("point loads must be finite")
        self.last_loads = self._fb
        c6 = clock()
        self.mpm.advance_to(t + dt)
        c7 = clock()
        if exchange.interface_row(xb, idx, self._x_before, self._fb, drop, self._drop_prev, self.thickness,
                                  dem.interface_work(), self.row, self._scratch):
            self.dropped_steps += 1
        c8 = clock()
        T["exchange"] += (c1 - c0) + (c5 - c4) + (c8 - c7)
        T["map"] += (c2 - c1) + (c6 - c5)
        T["interface"] += c3 - c2
        T["dem"] += c4 - c3
        T["mpm"] += c7 - c6
