"""Banded LU of the implicit Newton matrix without row swaps, in band storage (compact, or gbtrf's layout) (numba).

The row-equilibrated Newton matrix (kernels.to_band) is mass-dominated at the steps the implicit scheme takes
(m / (beta dt^2) on the diagonal; condition number 2.2 for the h = 5 mm Bui matrix on Kratos' discretization), and
partial pivoting rarely swaps a row there. `factor` is partial-pivoting LU on the condition that it swaps none: at
every column it checks the pivot rule of LAPACK's gbtf2 (idamax: a row swap iff some entry below the diagonal is
larger in magnitude than the diagonal one) and returns that column instead of swapping, so a caller falls back to
dgbtrf on a freshly built matrix. When it finishes, its factors are those of dgbtrf with identity pivots (the same
algorithm; bitwise the same factors on the captured Bui matrix) and `solve` is dgbtrs for them.

Threshold pivoting (the solver passes PIVOT_THRESHOLD = 0.1, UMFPACK's default): with tau < 1 the diagonal pivot
is kept while no entry below it exceeds it by more than 1 / tau (tau = 1: LAPACK's rule above); the growth of an
elimination step is then at most 1 + 1 / tau (11 for tau = 0.1; 2 for partial pivoting), the threshold partial
pivoting of sparse direct solvers (Duff, Erisman & Reid, Direct Methods for Sparse Matrices; SuperLU's
diag_pivot_thresh, UMFPACK's 0.1, MUMPS' 0.01). On the Bui matrices the columns that LAPACK's rule swaps have their
largest entry below the pivot within 3.3x of it (nodes with little mass): on Kratos' discretization 142 of 759
factorizations at h = 5 mm and 62 of 797 at h = 10 mm went to dgbtrf with tau = 1, none with tau = 1/2; on the
implicit bench's own scene (quadratic B-splines, friction base) with tau = 1/2 most still did (126 of ~190 over 40
steps at h = 10 mm, 125 of ~220 at 5 mm; each failed attempt sends the next 1, 2, 4, .. to dgbtrf), with tau = 0.3
and 0.1 none: +16-19 % MP-steps/s, the same Newton iterations (194 / 224 against 196 / 223). Those factors are as
accurate as dgbtrf's (twentieth session, every factorization that needed tau < 1/2 over 60 steps at 10 mm and 25 at
5 mm, 155 in all: relative residual of the solve <= 4.0e-15 against LAPACK's <= 4.1e-15, solutions within 2.7e-14,
growth max |U| / max |A| <= 2.9). The factors differ from dgbtrf's (which swaps) by round-off of the solution.

Why: dgbtrf keeps room for the fill of row swaps and runs small blocked panels; here (half-bandwidth 45, 1,722
dofs) it took 0.65 ms against 0.43 ms for this kernel (the solve 0.064 against 0.045 ms).

Storage (kernels.to_band): column j of A in row j of a C-order array, A[i, j] at ab[j, c0 + i - j], rows i from
j - ku to j + kl. c0 = ku: the compact layout (`band`: kl + ku + 1 entries per column, at least 8), the one the
solver uses; c0 = kl + ku: gbtrf's (transposed to C order; its first kl entries per column are the fill of row
swaps, which this LU never makes). ab has n + 1 rows (the last a spill row). The compact layout keeps the Newton
matrix's band in 1.27 instead of 1.90 MB (h = 5 mm on Kratos' discretization, 1,744 dofs, bw 45), so to_band +
factor fit the 2 MB L2 cache together: 142 + 448 -> 88 + 443 us, the same factors bit for bit. Right-looking,
panels of NB = 8 columns: the panel factored column by column, U12 (the panel rows of the next ku columns) by a unit
lower triangular solve in a dense buffer, then A22 -= L21 U12 with the eight multipliers of a row in registers, two
columns per pass, rows padded to a multiple of 8 (the padding reads and writes up to 7 entries past a column's
band, into the start of the next row of ab or the spill row, where it subtracts exact zeros and changes nothing).
"""
from __future__ import annotations

import numpy as np
from numba import njit

NB = 8      # panel width (the trailing update below is written out for 8)
PIVOT_THRESHOLD = 0.1     # tau of the threshold pivoting (the implicit solver's; UMFPACK's default); 1 = LAPACK's


def band(n, kl, ku):
    """Zeroed compact band storage for n unknowns (c0 = ku; rows >= 8 entries so the padding stays in the array)."""
    return np.zeros((n + 1, max(kl + ku + 1, NB)))


@njit(cache=True, fastmath={"contract"})
def factor(ab, n, kl, ku, c0, tau=1.0, k_lo=0, k_hi=-1):
    """In place. Returns -1 when factored; k >= 0 when (threshold tau) partial pivoting would swap a row at column k
    (some |l_ik| tau > |pivot|; ab is then partly factored: rebuild it for dgbtrf); -2 - k for a zero pivot
    (singular matrix) at column k. Eliminates columns k_lo .. k_hi - 1 only (default all): with k_hi < n the rest
    of the matrix is left as the Schur complement (the halves of the twisted factorization below)."""
    if k_hi < 0:
        k_hi = n
    LD = ab.shape[1]
    flat = ab.reshape(-1)
    M = (kl + 7) // 8 * 8
    MU = (ku + 7) // 8 * 8
    Lt = np.zeros((NB, M))      # L21 transposed: Lt[kk, rr] = L[r0 + rr, k0 + kk]
    Ub = np.zeros((NB, MU))     # U12: Ub[kk, cc] = U[k0 + kk, k0 + nb + cc]
    for k0 in range(k_lo, k_hi, NB):
        nb = min(NB, k_hi - k0)
        for k in range(k0, k0 + nb):        # the panel, right-looking within it
            m = min(kl, n - 1 - k)
            col = flat[k * LD + c0 + 1:k * LD + c0 + 1 + m]
            d = flat[k * LD + c0]
            ad = abs(d)
            swap = False
            for r in range(m):
                swap |= abs(col[r]) * tau > ad
            if swap:
                return k
            if d == 0.0:
                return -2 - k
            rd = 1.0 / d                    # gbtf2 scales by the reciprocal
            for r in range(m):
                col[r] *= rd
            for j in range(k + 1, min(k0 + nb, k + ku + 1)):
                o = j * LD + c0 + k + 1 - j
                u = flat[o - 1]
                cj = flat[o:o + m]
                for r in range(m):
                    cj[r] -= u * col[r]
        r0 = k0 + nb
        cend = min(n, r0 + ku)
        ncol = cend - r0
        for kk in range(NB):                # U12 into the buffer (zero outside the band)
            ub = Ub[kk]
            ub[:] = 0.0
            if kk < nb:
                k = k0 + kk
                for cc in range(min(ncol, ku + kk - nb + 1)):
                    c = r0 + cc
                    ub[cc] = flat[c * LD + c0 + k - c]
        for kk in range(1, nb):             # U12 = L11^-1 A12, row by row
            uk = Ub[kk]
            for k2 in range(max(0, kk - kl), kk):    # L[k0 + kk, k0 + k2] inside the band
                lv = flat[(k0 + k2) * LD + c0 + kk - k2]
                u2 = Ub[k2]
                for cc in range(MU):
                    uk[cc] -= lv * u2[cc]
        for kk in range(nb):
            k = k0 + kk
            for cc in range(min(ncol, ku + kk - nb + 1)):
                c = r0 + cc
                flat[c * LD + c0 + k - c] = Ub[kk, cc]
        if r0 >= n:
            break
        for kk in range(NB):                # L21 into the buffer (rows r0 .. k + kl, < n; element loops: as slice
            m = 0                           # assignments these copies took 81 of 430 us at h = 5 mm)
            if kk < nb:
                k = k0 + kk
                m = max(0, min(kk + kl - nb + 1, n - r0))
                o = k * LD + c0 + r0 - k
                for rr in range(m):
                    Lt[kk, rr] = flat[o + rr]
            for rr in range(m, M):
                Lt[kk, rr] = 0.0
        cc = 0
        while cc < ncol:                    # A22 -= L21 U12: columns r0 + cc (and + 1), rows r0 .. r0 + M - 1
            o = (r0 + cc) * LD + c0 - cc       # row r0 of column r0 + cc
            u0, u1, u2, u3, u4, u5, u6, u7 = (Ub[0, cc], Ub[1, cc], Ub[2, cc], Ub[3, cc], Ub[4, cc], Ub[5, cc],
                                              Ub[6, cc], Ub[7, cc])
            cv = flat[o:o + M]
            if cc + 1 < ncol:
                w0, w1, w2, w3, w4, w5, w6, w7 = (Ub[0, cc + 1], Ub[1, cc + 1], Ub[2, cc + 1], Ub[3, cc + 1],
                                                  Ub[4, cc + 1], Ub[5, cc + 1], Ub[6, cc + 1], Ub[7, cc + 1])
                cw = flat[o + LD - 1:o + LD - 1 + M]
                for rr in range(M):
                    l0, l1, l2, l3 = Lt[0, rr], Lt[1, rr], Lt[2, rr], Lt[3, rr]
                    l4, l5, l6, l7 = Lt[4, rr], Lt[5, rr], Lt[6, rr], Lt[7, rr]
                    cv[rr] = cv[rr] - l0 * u0 - l1 * u1 - l2 * u2 - l3 * u3 - l4 * u4 - l5 * u5 - l6 * u6 - l7 * u7
                    cw[rr] = cw[rr] - l0 * w0 - l1 * w1 - l2 * w2 - l3 * w3 - l4 * w4 - l5 * w5 - l6 * w6 - l7 * w7
                cc += 2
            else:
                for rr in range(M):
                    cv[rr] = (cv[rr] - Lt[0, rr] * u0 - Lt[1, rr] * u1 - Lt[2, rr] * u2 - Lt[3, rr] * u3
                              - Lt[4, rr] * u4 - Lt[5, rr] * u5 - Lt[6, rr] * u6 - Lt[7, rr] * u7)
                cc += 1
    return -1


@njit(cache=True, fastmath={"contract"}, inline="always")
def _forward(ab, n, kl, c0, b, j0, j1):
    """b <- L^-1 b over L's columns j0 .. j1 - 1 (unit lower, n rows; by columns over slices: vectorised)."""
    for j in range(j0, j1):
        m = min(kl, n - 1 - j)
        bj = b[j]
        lv = ab[j, c0 + 1:c0 + 1 + m]
        bv = b[j + 1:j + 1 + m]
        for r in range(m):
            bv[r] -= bj * lv[r]


@njit(cache=True, fastmath={"contract"}, inline="always")
def _backward(ab, ku, c0, b, j0, j1):
    """b <- U^-1 b over U's columns j1 - 1 down to j0 (each also updates the rows above it, down to row 0)."""
    for j in range(j1 - 1, j0 - 1, -1):
        xj = b[j] / ab[j, c0]
        b[j] = xj
        m = min(ku, j)
        uv = ab[j, c0 - m:c0]
        bv = b[j - m:j]
        for r in range(m):
            bv[r] -= xj * uv[r]


@njit(cache=True, fastmath={"contract"})
def solve(ab, n, kl, ku, c0, b):
    """b <- U^-1 L^-1 b with the factors of `factor` (forward, then back substitution, by columns)."""
    _forward(ab, n, kl, c0, b, 0, n)
    _backward(ab, ku, c0, b, 0, n)
    return b


# ---- twisted (two-sided) factorization: two threads each eliminate one end of the band --------------------------
# The unknowns split into T = [0, m), a separator S = [m, m + bw) and B = [m + bw, n): T and B do not couple (their
# distance exceeds the half-bandwidth bw). One thread eliminates T from the top (partial LU of A[T+S, T+S], in
# `top`), the other B from the bottom (partial LU of A[S+B, S+B] with its S x S block zero, in `bot` reversed:
# A[i, j] at bot[n - 1 - j, c0 + j - i], so its elimination also runs over the first columns); the separator's
# Schur complement is the sum of the two S x S blocks and is factored last, in `top`, by `factor` on its last bw
# columns. The same arithmetic on one thread (the halves one after the other): bitwise the same factors and
# solutions for any thread count. Block elimination without row swaps, so the same threshold rule guards every
# pivot (a column that would need a swap sends the matrix to gbtrf, as for `factor`). The idea of two-sided
# ("twisted", BABE) elimination of banded and tridiagonal systems: Hegland, Numer. Math. 59 (1991) 453-472; van der
# Vorst, Parallel Comput. 5 (1987) 303-311.

def twisted_split(n, bw):
    """m, the first separator unknown, for n unknowns of half-bandwidth bw; 0 when the band is too short to split
    (n < 4 bw: each half would hold less than 1.5 bw columns)."""
    if bw < 1 or n < 4 * bw:
        return 0
    return (n - bw) // 2


def twisted_bands(n, bw, m):
    """Zeroed compact storage of the two halves: top (T + S, m + bw unknowns), bottom (S + B reversed, n - m)."""
    return band(m + bw, bw, bw), band(n - m, bw, bw)


@njit(cache=True)
def join_separator(top, bot, n, m, bw, c0):
    """top's S x S block += bot's (the Schur complements of T and of B), in that order."""
    for j in range(m, m + bw):
        for i in range(m, m + bw):
            top[j, c0 + i - j] += bot[n - 1 - j, c0 + j - i]


@njit(cache=True, fastmath={"contract"})
def solve_twisted(top, bot, n, m, bw, c0, b):
    """b <- A^-1 b with the twisted factors (top factored through S, bot through B); the bottom half in a reversed
    copy y (y[r] = b[n - 1 - r], its S part from zero)."""
    nt, nbot = m + bw, n - m
    mb = nbot - bw                       # |B|
    y = np.zeros(nbot)
    for r in range(mb):
        y[r] = b[n - 1 - r]
    _forward(top, nt, bw, c0, b, 0, m)       # T's columns (rows up to S)
    _forward(bot, nbot, bw, c0, y, 0, mb)    # B's columns (rows up to S), reversed
    for r in range(mb, nbot):            # S gets B's part
        b[n - 1 - r] += y[r]
    _forward(top, nt, bw, c0, b, m, nt)      # S's own L
    _backward(top, bw, c0, b, 0, nt)         # S, then T (top's U)
    for r in range(mb, nbot):            # B: S's columns reach B's rows (local < mb) only, then B's own U
        xr = b[n - 1 - r]
        y[r] = xr
        lo = max(0, r - bw)
        if lo < mb:
            uv = bot[r, c0 + lo - r:c0 + mb - r]
            yv = y[lo:mb]
            for q in range(mb - lo):
                yv[q] -= xr * uv[q]
    _backward(bot, bw, c0, y, 0, mb)
    for r in range(mb):
        b[n - 1 - r] = y[r]
    return b
