"""The interleaved 1 / 2-thread scaling benches (coupler/bench.py lattice_pairs, coupler/mpm/bench.py
bench_mpm_scaling): structure of what they report, tiny sizes, no timed assert."""
import numba
import numpy as np

from coupler import bench


def _check(sc, pairs):
    assert sc["pairs"] == pairs and len(sc["ratios"]) == pairs and sc["ratio"]["n"] == pairs
    r1 = [v for k, v in sc.items() if k.endswith("_1t") and isinstance(v, list)][0]
    r2 = [v for k, v in sc.items() if k.endswith("_2t") and isinstance(v, list)][0]
    assert np.allclose(sc["ratios"], np.array(r2) / np.array(r1), rtol=1e-12)
    assert sc["median_1t"] == float(np.median(r1)) and sc["median_2t"] == float(np.median(r2))
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS


def test_lattice_pairs_structure():
    sc = bench.lattice_pairs(pairs=2, nx=3, ny=3, nz=3, steps=5, probe=True)
    _check(sc, 2)
    assert sc["particles"] == 27
    assert set(sc["host_probe"]) == {"fma", "stream", "launch_us"} and sc["host_probe"]["fma"]["ratio"]["n"] == 2
    line = bench.scaling_line("DEM lattice", sc)
    assert "pair ratio median" in line and "of 2 pairs below 1.8x" in line and "host probe FMA" in line


def test_mpm_scaling_structure():
    from coupler.mpm.bench import bench_mpm_scaling
    sc = bench_mpm_scaling(pairs=1, steps=2, probe=False)
    _check(sc, 1)
    assert sc["points"] == 12800 and "host_probe" not in sc
    assert sc["ms_per_step_by_kernel_1t"]["p2g"] > 0 and sc["ms_per_step_by_kernel_2t"]["total"] > 0
