"""coupler/loops.py: the unsigned loop index visits exactly range(lo, hi), empty ranges included, and a kernel
reading arrays through it gives the values of the signed loop."""
import numpy as np
from hypothesis import given, settings, strategies as st
from numba import njit

from coupler.loops import items, unsigned


@njit(cache=True)
def _visit(lo, hi, out):
    n = 0
    for i in items(lo, hi):
        out[n] = i
        n += 1
    return n


@njit(cache=True)
def _gather_sum(idx, a, lo, hi):
    s = 0.0
    for k in items(lo, hi):
        s += a[unsigned(idx[k])]
    return s


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 50), st.integers(0, 50))
def test_items_is_range(lo, hi):
    out = np.full(64, -1, np.int64)
    n = _visit(lo, hi, out)
    assert list(out[:n]) == list(range(lo, hi))


def test_indirect_read_matches_numpy():
    rng = np.random.default_rng(3)
    a = rng.random(100)
    idx = rng.integers(0, 100, 40).astype(np.int32)
    assert _gather_sum(idx, a, 5, 33) == sum(a[idx[k]] for k in range(5, 33))
