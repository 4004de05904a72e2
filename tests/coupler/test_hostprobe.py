"""coupler/hostprobe.py: structure and sanity of the host probe and of the interleaved 1 / 2-thread timing (no timed
assert: the machine is shared, only what the numbers are and how they are combined is checked)."""
import numba
import numpy as np
import pytest

from coupler import hostprobe as hp


def test_kernels_compute_what_they_say():
    out = np.zeros(4)
    hp._fma(out, 3)
    a = np.arange(8.0)                      # 8 chains from out[i] + k, 3 steps of a b + c, summed
    for _ in range(3):
        a = a * 0.999999 + 1e-7
    assert np.allclose(out, a.sum(), rtol=1e-14)
    a, b, c = np.zeros(5), np.arange(5.0), np.full(5, 2.0)
    hp._triad(a, b, c, 0.5)
    assert np.array_equal(a, b + 1.0)


def test_interleave_alternates_the_order_and_pairs_the_ratios():
    calls = []
    seq1, seq2 = iter([1.0, 2.0, 4.0]), iter([2.0, 3.0, 4.0])

    def f1():
        calls.append(1)
        return next(seq1)

    def f2():
        calls.append(2)
        return next(seq2)
    r = hp.interleave(f1, f2, 3)
    assert calls == [1, 2, 2, 1, 1, 2]                      # order flips every pair
    assert r["rates_1"] == [1.0, 2.0, 4.0] and r["rates_2"] == [2.0, 3.0, 4.0]
    assert r["ratios"] == [2.0, 1.5, 1.0]
    s = r["ratio"]
    assert s["median"] == 1.5 and s["min"] == 1.0 and s["max"] == 2.0 and s["n"] == 3
    assert s["q25"] == 1.25 and s["q75"] == 1.75
    assert s["below_1.8"] == 2 and s["below_1.6"] == 2
    assert r["wall_s"] >= 0.0


def test_interleave_many_runs_the_benches_pair_by_pair():
    calls = []

    def mk(tag, rate):
        def f():
            calls.append(tag)
            return rate
        return f
    r = hp.interleave_many({"a": (mk("a1", 1.0), mk("a2", 2.0)), "b": (mk("b1", 4.0), mk("b2", 2.0))}, 2)
    assert calls == ["a1", "a2", "b1", "b2", "a2", "a1", "b2", "b1"]
    assert r["a"]["ratios"] == [2.0, 2.0] and r["b"]["ratios"] == [0.5, 0.5]
    assert r["a"]["ratio"]["median"] == 2.0 and r["b"]["ratio"]["below_1.6"] == 2


def test_summary_of_nothing():
    assert hp.summary([]) == {"n": 0}


def test_steal_percent():
    assert hp.steal_percent((10, 1000), (30, 2000)) == pytest.approx(2.0)
    assert hp.steal_percent(None, (1, 2)) is None and hp.steal_percent((5, 10), (5, 10)) is None
    c = hp.steal_counters()
    if c is not None:                                      # Linux: steal <= total jiffies
        assert 0 <= c[0] <= c[1]


def test_probe_structure_and_thread_count_restored():
    r = hp.probe(pairs=1)
    for k in ("fma", "stream"):
        assert len(r[k]["ratios"]) == 1 and r[k]["ratio"]["n"] == 1
        assert all(x > 0 and np.isfinite(x) for x in r[k]["rates_1"] + r[k]["rates_2"])
    assert r["launch_us"]["1t"] > 0 and r["launch_us"]["2t"] > 0
    assert r["host"]["numba_threads"] == numba.config.NUMBA_NUM_THREADS
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS


def test_on_threads_sets_the_count():
    seen = []
    f = hp.on_threads(1, lambda: seen.append(numba.get_num_threads()) or 1.0)
    try:
        assert f() == 1.0 and seen == [1]
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
