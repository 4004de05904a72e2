"""The compiled exchange (coupler/coupling/exchange.py) gives the bits of the numpy expressions it replaced."""
from __future__ import annotations

import numpy as np

from coupler.coupling import exchange
from coupler.coupling.mappers.linear import LinearMapper


def test_pairwise_sum_is_numpys_sum_bit_for_bit():
    rng = np.random.default_rng(7)
    for n in list(range(0, 300)) + [511, 1000, 4097, 9000]:
        a = rng.standard_normal(n) * 10.0 ** rng.integers(-6, 6, n)
        assert exchange.pairwise_sum(a) == np.sum(a), n
        b = rng.standard_normal((n, 3))
        assert exchange.pairwise_sum(b[:, 1]) == b[:, 1].sum(), n          # a strided column
        assert exchange.pairwise_sum(b.reshape(-1)) == np.sum(b), n       # a contiguous (n, 3) array
    assert str(exchange.pairwise_sum(np.array([-0.0]))) == str(np.sum(np.array([-0.0])))


def _linear_mapper():
    s = np.linspace(0.0, 1.0, 9)
    origin = np.column_stack([s, 0.3 * s ** 2])
    dest = np.column_stack([np.linspace(0.0, 1.0, 5), 0.3 * np.linspace(0.0, 1.0, 5) ** 2 + 1e-3])
    return LinearMapper(origin, [(0, 9, False)], dest)


def test_mapper_kernels_equal_the_numpy_expressions():
    m = _linear_mapper()
    assert not m.identity
    rng = np.random.default_rng(3)
    u = rng.standard_normal((9, 2))
    ref = m.w[:, 0:1] * u[m.cols[:, 0]] + m.w[:, 1:2] * u[m.cols[:, 1]]
    np.testing.assert_array_equal(m.kinematics(u), ref)
    f = rng.standard_normal((5, 3))[:, :2]                     # strided, as DEMPartition.interface_forces
    ref = np.column_stack([np.bincount(m._c, weights=m._w * np.concatenate([f[:, k], f[:, k]]), minlength=9)
                           for k in range(2)]) / 0.1
    out = np.empty((9, 2))
    exchange.map_forces(f, m._c, m._w, False, 0.1, out)
    np.testing.assert_array_equal(out, ref)


def test_point_loads_refuses_non_finite_forces():
    m = _linear_mapper()
    F = np.zeros((5, 2))
    F[2, 1] = np.nan
    fb = np.zeros((12, 2))
    ok = exchange.point_loads(F, m._c, m._w, False, 0.1, np.zeros((9, 2)), fb, np.arange(3, 12), np.zeros(7))
    assert not ok and not fb.any()
