"""coupler/mpm/implicit/band_lu.py: LU without row swaps in gbtrf storage and in the compact layout, against LAPACK's
dgbtrf / dgbtrs."""
import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.linalg.lapack import dgbtrf, dgbtrs

from coupler.mpm.implicit import band_lu as BL


def band_storage(A, kl, ku):
    """A (n x n, zero outside the band) in the C-order transposed gbtrf layout of kernels.to_band, + the spill row."""
    n = A.shape[0]
    ab = np.full((n + 1, 2 * kl + ku + 1), np.nan)     # the fill rows and the spill row are not read as data
    ab[:n, kl:] = 0.0
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[j, kl + ku + i - j] = A[i, j]
    return ab


def compact_storage(A, kl, ku):
    """A in band_lu's compact layout (c0 = ku): BL.band with the band entries set, the spill row NaN."""
    n = A.shape[0]
    ab = BL.band(n, kl, ku)
    ab[n] = np.nan
    for j in range(n):
        for i in range(max(0, j - ku), min(n, j + kl + 1)):
            ab[j, ku + i - j] = A[i, j]
    return ab


def random_band(rng, n, kl, ku, dominance):
    A = rng.standard_normal((n, n))
    i, j = np.indices((n, n))
    A[(i - j > kl) | (j - i > ku)] = 0.0
    A[np.diag_indices(n)] = dominance * (np.abs(A).sum(axis=0) + 1.0) * np.sign(rng.standard_normal(n))
    return A


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 90), kl=st.integers(0, 30), ku=st.integers(0, 30), seed=st.integers(0, 2**31 - 1))
def test_no_swap_lu_is_lapacks_with_identity_pivots(n, kl, ku, seed):
    """Column-diagonally dominant: partial pivoting swaps nothing; factors and solution equal dgbtrf / dgbtrs's
    (the same algorithm; round-off aside: at most a few ulps of the solution)."""
    kl, ku = min(kl, n - 1), min(ku, n - 1)
    rng = np.random.default_rng(seed)
    A = random_band(rng, n, kl, ku, 1.0)
    ab = band_storage(A, kl, ku)
    lu, piv, info = dgbtrf(np.asfortranarray(ab[:n].T.copy()), kl, ku)
    assert BL.factor(ab, n, kl, ku, kl + ku) == -1
    assert info == 0 and np.array_equal(piv, np.arange(n))
    band = np.zeros_like(lu)
    band[kl:] = ab[:n, kl:].T
    assert np.allclose(band[kl:], lu[kl:], rtol=1e-13, atol=1e-15)
    b = rng.standard_normal(n)
    x = BL.solve(ab, n, kl, ku, kl + ku, b.copy())
    xl, _ = dgbtrs(lu, kl, ku, b, piv)
    assert np.allclose(x, xl, rtol=1e-12, atol=1e-14)
    assert np.allclose(A @ x, b, rtol=1e-11, atol=1e-12)
    # the compact layout (no fill entries; the padded rows of the update run into the next column's entries and
    # the spill row): the same factors and solution bit for bit
    ac = compact_storage(A, kl, ku)
    assert BL.factor(ac, n, kl, ku, ku) == -1
    assert np.array_equal(ac[:n, :kl + ku + 1], ab[:n, kl:])
    assert np.array_equal(BL.solve(ac, n, kl, ku, ku, b.copy()), x)


def test_reports_the_column_where_partial_pivoting_would_swap():
    """A sub-diagonal entry larger than the pivot at column 5 (after the updates): returned, not swapped; and a zero
    column gives the zero-pivot code."""
    rng = np.random.default_rng(3)
    n, kl, ku = 12, 3, 2
    A = random_band(rng, n, kl, ku, 1.0)
    A[7, 5] = 10.0 * abs(A[5, 5])
    _, piv, _ = dgbtrf(np.asfortranarray(band_storage(A, kl, ku)[:n].T.copy()), kl, ku)
    first_swap = int(np.flatnonzero(piv != np.arange(n))[0])
    assert first_swap == 5
    assert BL.factor(band_storage(A, kl, ku), n, kl, ku, kl + ku) == first_swap
    Z = random_band(rng, n, kl, ku, 1.0)
    Z[:, 4] = 0.0
    assert BL.factor(band_storage(Z, kl, ku), n, kl, ku, kl + ku) == -2 - 4


def test_threshold_pivoting_keeps_a_pivot_within_one_over_tau():
    """tau = 1/2: an entry below the pivot up to 2x larger keeps the diagonal pivot (no swap; the solution is that of
    A to round-off), a larger one is reported like a swap; tau = 1 reports the first (LAPACK's rule)."""
    rng = np.random.default_rng(5)
    n, kl, ku = 14, 3, 3
    A = random_band(rng, n, kl, ku, 1.0)
    A[8, 6] = 1.6 * abs(A[6, 6])      # after the updates still in (1, 2) x the pivot of column 6
    lu, piv, _ = dgbtrf(np.asfortranarray(band_storage(A, kl, ku)[:n].T.copy()), kl, ku)
    assert int(np.flatnonzero(piv != np.arange(n))[0]) == 6
    assert BL.factor(band_storage(A, kl, ku), n, kl, ku, kl + ku, 1.0) == 6
    ab = band_storage(A, kl, ku)
    assert BL.factor(ab, n, kl, ku, kl + ku, 0.5) == -1
    b = rng.standard_normal(n)
    x = BL.solve(ab, n, kl, ku, kl + ku, b.copy())
    xl, _ = dgbtrs(lu, kl, ku, b, piv)
    assert np.allclose(x, xl, rtol=1e-12, atol=1e-13)
    assert np.allclose(A @ x, b, rtol=1e-12, atol=1e-13)
    A[8, 6] = 3.0 * abs(A[6, 6])
    assert BL.factor(band_storage(A, kl, ku), n, kl, ku, kl + ku, 0.5) == 6
    # the solver's tau (0.1): the 3x entry keeps the diagonal pivot, the solution is A's to round-off; 15x is reported
    assert BL.PIVOT_THRESHOLD == 0.1
    ab = band_storage(A, kl, ku)
    assert BL.factor(ab, n, kl, ku, kl + ku, BL.PIVOT_THRESHOLD) == -1
    x = BL.solve(ab, n, kl, ku, kl + ku, b.copy())
    assert np.allclose(A @ x, b, rtol=1e-12, atol=1e-13)
    A[8, 6] = 15.0 * abs(A[6, 6])
    assert BL.factor(band_storage(A, kl, ku), n, kl, ku, kl + ku, BL.PIVOT_THRESHOLD) == 6
