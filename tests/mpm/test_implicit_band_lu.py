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


def test_factor_over_two_column_ranges_is_one_factor():
    """factor(.., k_lo, k_hi) eliminates a column range and leaves the Schur complement: columns [0, k) then [k, n)
    give the factors of one call bit for bit when k is a multiple of the panel width (the same panels)."""
    rng = np.random.default_rng(11)
    n, kl, ku = 70, 9, 7
    A = random_band(rng, n, kl, ku, 1.0)
    one = compact_storage(A, kl, ku)
    assert BL.factor(one, n, kl, ku, ku) == -1
    two = compact_storage(A, kl, ku)
    assert BL.factor(two, n, kl, ku, ku, 1.0, 0, 3 * BL.NB) == -1
    assert BL.factor(two, n, kl, ku, ku, 1.0, 3 * BL.NB, n) == -1
    assert np.array_equal(one[:n], two[:n])


def csr_system(rng, n, bw, held_frac=0.1):
    """The solver's inputs of kernels.to_band for a random band matrix of half-bandwidth bw: CSR tangent (every
    band entry stored), diagonal positions, mass term, held rows, no sliding rows; and the dense matrix they define
    (held rows: identity)."""
    import scipy.sparse as sp
    T = random_band(rng, n, bw, bw, 0.0)
    dominant = 2.0 * (np.abs(T).sum(axis=0) + np.abs(T).sum(axis=1) + 1.0)
    T[np.diag_indices(n)] = dominant * np.sign(rng.standard_normal(n))
    T *= 10.0 ** rng.uniform(-1, 1, size=(n, 1))      # rows of different size (to_band equilibrates them)
    i, j = np.indices((n, n))
    pattern = np.abs(i - j) <= bw
    C = sp.csr_matrix((T[pattern], (i[pattern], j[pattern])), shape=(n, n))
    C.sort_indices()
    rowptr, cols, data = C.indptr.astype(np.int64), C.indices.astype(np.int64), C.data.copy()
    diag = np.array([rowptr[r] + int(np.flatnonzero(cols[rowptr[r]:rowptr[r + 1]] == r)[0]) for r in range(n)])
    madd = np.abs(rng.standard_normal(n)) * np.abs(T).max(axis=1) * np.sign(np.diag(T))
    held = rng.random(n) < held_frac
    A = T + np.diag(madd)
    A[held] = 0.0
    A[held, held] = 1.0
    return (data, rowptr, cols, diag, madd, held, np.full(n, -1, np.int64), np.zeros(n)), A


def twisted(args, n, bw, tau=BL.PIVOT_THRESHOLD):
    from coupler.mpm.implicit import kernels as IK
    m = BL.twisted_split(n, bw)
    top, bot = BL.twisted_bands(n, bw, m)
    rscale = np.full(n, np.nan)
    k = IK.to_band_factor_twisted(*args, bw, top, bot, m, rscale, tau)
    return k, m, top, bot, rscale


@settings(max_examples=25, deadline=None)
@given(bw=st.integers(1, 24), extra=st.integers(0, 150), seed=st.integers(0, 2**31 - 1))
def test_twisted_factorization_solves_the_band_system(bw, extra, seed):
    """kernels.to_band_factor_twisted (the two halves built and factored, one per thread, then the separator) and
    band_lu.solve_twisted: the solution of the row-equilibrated system is that of the dense matrix to round-off
    and agrees with the one-sided band_lu path (to_band, factor, solve)."""
    from coupler.mpm.implicit import kernels as IK
    n = 4 * bw + extra
    rng = np.random.default_rng(seed)
    args, A = csr_system(rng, n, bw)
    k, m, top, bot, rscale = twisted(args, n, bw)
    assert m > 0 and k == -1
    b = rng.standard_normal(n)
    x = BL.solve_twisted(top, bot, n, m, bw, bw, rscale * b)
    assert np.allclose(A @ x, b, rtol=1e-11, atol=1e-11 * np.abs(b).max())
    ab = BL.band(n, bw, bw)
    rs1 = np.ones(n)
    IK.to_band(*args, bw, ab, bw, rs1, True)
    assert np.array_equal(rs1, rscale)
    assert BL.factor(ab, n, bw, bw, bw, BL.PIVOT_THRESHOLD) == -1
    x1 = BL.solve(ab, n, bw, bw, bw, rs1 * b)
    assert np.allclose(x, x1, rtol=1e-10, atol=1e-12 * np.abs(x1).max())


def test_twisted_factorization_is_bitwise_the_same_on_1_and_2_threads():
    from tests.conftest import on_1_and_2_threads
    n, bw = 400, 20
    args, _ = csr_system(np.random.default_rng(2), n, bw)
    b = np.random.default_rng(3).standard_normal(n)

    def run():
        k, m, top, bot, rscale = twisted(args, n, bw)
        return [np.array([k]), top, bot, rscale, BL.solve_twisted(top, bot, n, m, bw, bw, rscale * b)]

    for a, c in zip(*on_1_and_2_threads(run)):
        assert np.array_equal(a, c)


def test_twisted_factorization_reports_swaps_and_zero_pivots_in_global_numbering():
    """The first column each half eliminates (0 from the top, n - 1 from the bottom, where the entries 'below' the
    pivot are those above the diagonal): a pivot far below its row's other entries (after the row equilibration of
    to_band, an entry below it then exceeds it by more than 1 / tau), or a zero column, gives band_lu.factor's code
    in the matrix's own numbering (k, or -2 - k)."""
    n, bw = 200, 10
    assert BL.twisted_split(n, bw) > 0
    for col in (0, n - 1):
        args, _ = csr_system(np.random.default_rng(5), n, bw, held_frac=0.0)
        data, rowptr, cols, diag, madd = args[:5]
        data[diag[col]] = 1e-6 * abs(data[rowptr[col]:rowptr[col + 1]]).max()
        madd[col] = 0.0
        assert twisted(args, n, bw)[0] == col
        args, _ = csr_system(np.random.default_rng(6), n, bw, held_frac=0.0)
        data, rowptr, cols, diag, madd = args[:5]
        data[cols == col] = 0.0
        madd[col] = 0.0
        assert twisted(args, n, bw)[0] == -2 - col
