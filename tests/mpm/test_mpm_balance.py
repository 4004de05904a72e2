"""The work split of P2G and of the grid update by measured cost (kernels.colour_groups / block_groups, Grid.scost):
the groups partition the strips, follow the measured cost, fall back to point counts before a measurement, and
never change a result (bitwise identical for 1 and 2 threads: test_mpm_core.py)."""
import numpy as np

from coupler.mpm import kernels as K
from coupler.mpm.bench import SCENE
from coupler.mpm.solver import MPMSolver
from coupler.scene import load_scene


def _start(counts):
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def test_bounds_split_by_cost():
    out = np.empty(3, np.int64)
    K._bounds(np.array([1, 1, 1, 1, 10, 10], np.int64), 2, out)
    assert list(out) == [0, 5, 6]            # half of 24 is crossed in item 4: boundary after it (nearer)
    K._bounds(np.array([5, 5, 5, 5], np.int64), 2, out)
    assert list(out) == [0, 2, 4]


def test_colour_groups_follow_the_measured_cost_and_fall_back_to_points():
    counts = np.array([10, 10, 10, 10, 10, 10, 10, 10])          # 8 strips, equal points
    start = _start(counts)
    by_points = K.colour_groups(start, 2, 0, np.zeros(8, np.int64))   # unmeasured: point counts
    assert list(by_points[0]) == [0, 2, 4] and list(by_points[1]) == [0, 2, 4]
    cost = np.array([100, 100, 100, 100, 100, 100, 900, 100], np.int64)   # strip 6 (colour 0, k = 3) costs 9x
    g = K.colour_groups(start, 2, 0, cost)
    assert list(g[0]) == [0, 3, 4] and list(g[1]) == [0, 2, 4]
    assert np.array_equal(K.colour_groups(start, 2, 0, np.empty(0, np.int64)), by_points)   # no cost array
    cost[3] = 0                                                            # one strip of colour 1 unmeasured
    assert list(K.colour_groups(start, 2, 0, cost)[1]) == [0, 2, 4]


def test_measured_cost_is_capped():
    start = _start([1] * 12)                               # colour 0: strips 0, 2, ..., 10 (6 items)
    cost = np.full(12, 10, np.int64)
    cost[10] = 10 ** 9                                     # one strip timed across a preemption
    est = K._measured(cost, start, 0, 6)
    assert list(est[:5]) == [10] * 5 and est[5] == 4 * (50 + 10 ** 9) // 6
    cost[4] = 0                                            # not measured yet: no estimate
    assert K._measured(cost, start, 0, 6).shape == (0,)


def test_block_groups_fall_back_to_the_p2g_groups():
    start = _start([10] * 8)
    grp = K.colour_groups(start, 2, 0, np.zeros(8, np.int64))
    assert np.array_equal(K.block_groups(start, 2, np.zeros(8, np.int64), grp), grp[0])
    cost = np.array([1, 0, 1, 0, 1, 0, 50, 0], np.int64)                 # blocks at even indices only
    assert list(K.block_groups(start, 2, cost, grp)) == [0, 3, 4]


def test_solver_measures_every_strip():
    sc = load_scene(SCENE, overrides={"mpm.grid.cell_size": 0.01})
    sol = MPMSolver(sc)
    assert not sol._strip_cost.any()
    sol.advance(3)
    ns = len(sol.strip_start) - 1
    assert sol._strip_cost.shape == (2, ns)
    assert (sol._strip_cost[0] > 0).all()                  # every strip timed in P2G
    assert (sol._strip_cost[1, 0::2] > 0).all()            # every column block timed in the grid update
    occupied = np.diff(sol.strip_start) > 0
    assert sol._strip_cost[0][occupied].mean() > sol._strip_cost[0][~occupied].mean()
