"""Host probe: how far this host's cores can scale at the time a thread-scaling bench runs, measured beside it.

The machine is shared (a VM on 2 cores): its speed drifts by 20-40 % over minutes, so a 1-thread figure and a
2-thread figure taken a minute apart are not a ratio. The probe gives the two references a solver's ratio is read
against, each timed on 1 and 2 threads in the same way:
  fma       an FMA-bound loop (independent multiply-add chains per work item, no memory traffic): the host's compute
            scaling; ~2x on two free cores
  stream    a memory-bound loop (a[i] = b[i] + s c[i] over 3 x 16 MB, STREAM "triad", McCalpin 1995): the shared
            memory bandwidth (and what a neighbour VM takes of it); a memory-heavy solver cannot scale beyond it
  launch    the cost of an empty parallel region (numba prange over one item per thread), 1 and 2 threads [us]
  steal     /proc/stat steal time over the measurement [% of the CPU time]: time the hypervisor ran someone else
`interleave(f1, f2, pairs)` times a 1-thread block and a 2-thread block alternately (the order flips every pair) and
reports the ratio of each pair: host drift slower than a pair cancels in the ratio, drift faster than it shows as
spread (median and inter-quartile range, with the number of pairs below given ratios). Never used in a timed assert.
"""
from __future__ import annotations

import os
import time
from typing import Callable

import numba
import numpy as np
from numba import njit, prange

FMA_ITEMS = 64          # independent work items of the FMA loop (8 chains each): enough for an even split
FMA_ITERS = 40_000      # multiply-adds per chain: ~20 M FMA per call, ~10 ms on one core
STREAM_N = 2_000_000    # doubles per array of the triad: 3 x 16 MB, beyond the caches
SLOWER = (1.8, 1.6)     # pair ratios counted below (issue 13's goal 1.8x; 1.6x)


@njit(cache=True, parallel=True)
def _fma(out, iters):
    """out[i] <- 8 independent chains a <- a b + c (iters each); compute-bound, no memory traffic in the loop."""
    for i in prange(out.shape[0]):
        a0, a1, a2, a3 = out[i], out[i] + 1.0, out[i] + 2.0, out[i] + 3.0
        a4, a5, a6, a7 = out[i] + 4.0, out[i] + 5.0, out[i] + 6.0, out[i] + 7.0
        b, c = 0.999999, 1e-7
        for _ in range(iters):
            a0 = a0 * b + c
            a1 = a1 * b + c
            a2 = a2 * b + c
            a3 = a3 * b + c
            a4 = a4 * b + c
            a5 = a5 * b + c
            a6 = a6 * b + c
            a7 = a7 * b + c
        out[i] = a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7


@njit(cache=True, parallel=True)
def _triad(a, b, c, s):
    """STREAM triad a = b + s c (memory-bound: 24 bytes moved per 2 flops)."""
    for i in prange(a.shape[0]):
        a[i] = b[i] + s * c[i]


@njit(cache=True, parallel=True)
def _empty(x):
    """An empty parallel region, one item per thread (the launch cost)."""
    for i in prange(x.shape[0]):
        x[i] += 0.0


def steal_counters() -> tuple[int, int] | None:
    """(steal, total) jiffies of the aggregate cpu line of /proc/stat; None where there is none."""
    try:
        with open("/proc/stat") as f:
            parts = f.readline().split()
    except OSError:
        return None
    if not parts or parts[0] != "cpu" or len(parts) < 9:
        return None
    v = [int(x) for x in parts[1:]]
    return v[7], sum(v[:8])          # user nice system idle iowait irq softirq steal


def steal_percent(before, after) -> float | None:
    """Steal time between two steal_counters() readings, % of all CPU time (None without /proc/stat or no time)."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return 100.0 * (after[0] - before[0]) / (after[1] - before[1])


def on_threads(threads: int, fn: Callable[[], float]) -> Callable[[], float]:
    """fn run with numba's thread count set to `threads` (clamped to NUMBA_NUM_THREADS)."""
    t = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))

    def run() -> float:
        numba.set_num_threads(t)
        return fn()
    return run


def summary(ratios: list[float], slower=SLOWER) -> dict:
    """median, quartiles (q25, q75), min, max, n of pair ratios and how many fall below each value of `slower`."""
    r = np.asarray(ratios, float)
    if r.size == 0:
        return {"n": 0}
    q25, med, q75 = np.percentile(r, [25, 50, 75])
    out = {"median": float(med), "q25": float(q25), "q75": float(q75), "min": float(r.min()), "max": float(r.max()),
           "n": int(r.size)}
    for s in slower:
        out[f"below_{s:g}"] = int(np.sum(r < s))
    return out


def interleave_many(benches: dict[str, tuple[Callable[[], float], Callable[[], float]]], pairs: int) -> dict:
    """Pairs of blocks of each bench in turn: name -> (f1, f2), each returning a rate (work per second). Pair i of
    every bench runs f1 then f2 (even i) or f2 then f1 (odd i), so slow drift of the host speed cancels in the pair
    ratio f2 / f1 and a trend does not favour one side; the benches are interleaved pair by pair, so their ratios
    sample the same minutes. Returns name -> {rates_1, rates_2, ratios, ratio: summary(ratios)} and steal_percent
    over the whole measurement."""
    res = {k: {"rates_1": [], "rates_2": [], "ratios": []} for k in benches}
    s0 = steal_counters()
    t0 = time.perf_counter()
    for i in range(int(pairs)):
        for k, (f1, f2) in benches.items():
            if i % 2 == 0:
                r1 = f1()
                r2 = f2()
            else:
                r2 = f2()
                r1 = f1()
            res[k]["rates_1"].append(float(r1))
            res[k]["rates_2"].append(float(r2))
            res[k]["ratios"].append(float(r2 / r1))
    for k in benches:
        res[k]["ratio"] = summary(res[k]["ratios"])
    res["steal_percent"] = steal_percent(s0, steal_counters())
    res["wall_s"] = time.perf_counter() - t0
    return res


def interleave(f1: Callable[[], float], f2: Callable[[], float], pairs: int) -> dict:
    """interleave_many with one bench: rates_1, rates_2, ratios (f2 / f1 per pair), ratio summary, steal_percent."""
    r = interleave_many({"b": (f1, f2)}, pairs)
    out = r["b"]
    out["steal_percent"], out["wall_s"] = r["steal_percent"], r["wall_s"]
    return out


def fma_rate(items: int = FMA_ITEMS, iters: int = FMA_ITERS) -> Callable[[], float]:
    """A block of the FMA loop; returns multiply-adds per second."""
    out = np.zeros(items)

    def run() -> float:
        t0 = time.perf_counter()
        _fma(out, iters)
        return 8.0 * items * iters / (time.perf_counter() - t0)
    return run


def stream_rate(n: int = STREAM_N, reps: int = 4) -> Callable[[], float]:
    """A block of `reps` triads; returns bytes moved per second (3 arrays x 8 bytes per element)."""
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)

    def run() -> float:
        t0 = time.perf_counter()
        for _ in range(reps):
            _triad(a, b, c, 0.5)
        return 24.0 * n * reps / (time.perf_counter() - t0)
    return run


def launch_us(threads: int, calls: int = 2000) -> float:
    """Median cost of an empty parallel region on `threads` threads [us] (median of 20 blocks of calls / 20)."""
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    x = np.zeros(numba.get_num_threads())
    _empty(x)
    per = max(1, calls // 20)
    ts = []
    for _ in range(20):
        t0 = time.perf_counter()
        for _ in range(per):
            _empty(x)
        ts.append((time.perf_counter() - t0) / per)
    return 1e6 * float(np.median(ts))


def probe_benches() -> dict[str, tuple[Callable[[], float], Callable[[], float]]]:
    """The probe's two loops as interleave_many entries (1 thread, 2 threads), compiled and warmed up."""
    f, s = fma_rate(), stream_rate()
    out = {"fma": (on_threads(1, f), on_threads(2, f)), "stream": (on_threads(1, s), on_threads(2, s))}
    for f1, f2 in out.values():
        f1()
        f2()
    return out


def solver_blocks(solvers: dict, items: int, steps: int) -> tuple[Callable[[], float], Callable[[], float]]:
    """interleave_many entry for a solver bench: `solvers[t].advance(steps)` on t = 1 / 2 threads, each returning
    items * steps per second (particle- or MP-steps/s)."""
    def block(t: int) -> Callable[[], float]:
        def run() -> float:
            t0 = time.perf_counter()
            solvers[t].advance(steps)
            return items * steps / (time.perf_counter() - t0)
        return on_threads(t, run)
    return block(1), block(2)


def scaling_record(res: dict, key: str, probe: bool) -> dict:
    """The bench.json record of one interleave_many result: rates, pair ratios, medians, steal, wall time, and the
    host probe's loops beside it when they ran."""
    r = res[key]
    out = {"rates_1t": r["rates_1"], "rates_2t": r["rates_2"], "ratios": r["ratios"], "ratio": r["ratio"],
           "median_1t": float(np.median(r["rates_1"])), "median_2t": float(np.median(r["rates_2"])),
           "steal_percent": res["steal_percent"], "wall_s": res["wall_s"]}
    if probe:
        out["host_probe"] = {k: {"ratio": res[k]["ratio"], "ratios": res[k]["ratios"],
                                 "median_1t": float(np.median(res[k]["rates_1"])),
                                 "median_2t": float(np.median(res[k]["rates_2"]))} for k in ("fma", "stream")}
        out["host_probe"]["launch_us"] = {"1t": launch_us(1), "2t": launch_us(2)}
    out["host"] = host_state()
    return out


def host_state() -> dict:
    """Load average, CPU count, numba's thread count and threading layer (after a parallel call)."""
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    return {"loadavg": load, "cpu_count": os.cpu_count(), "numba_threads": numba.config.NUMBA_NUM_THREADS,
            "threading_layer": numba.threading_layer()}


def probe(pairs: int = 5) -> dict:
    """The host probe on its own: FMA and stream loops interleaved 1 / 2 threads for `pairs` pairs, launch cost,
    steal time, load. The thread count is restored to NUMBA_NUM_THREADS afterwards."""
    try:
        res = interleave_many(probe_benches(), pairs)
        res["launch_us"] = {"1t": launch_us(1), "2t": launch_us(2)}
        res["host"] = host_state()
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return res


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys
    print(json.dumps(probe(int(sys.argv[1]) if len(sys.argv) > 1 else 5), indent=1))
