"""Banded symmetric linear algebra, compiled: Cholesky, solves, products, inverse band.

Symmetric matrices are given as their lower band in scipy's layout,
``ab[d, j] = A[j + d, j]``, shape (b + 1, n) (:func:`scipy.linalg.cholesky_banded`
with ``lower=True``). Their Cholesky factors are kept column by column,
``lt[j, d] = L[j + d, j]``, shape (n, b + 1): the factorization (right-looking)
and the solves then walk memory in order, and several right-hand sides side by
side, shape (n, m), are solved in one sweep. At the sizes of a few rods (tens
to hundreds of dofs, 9 to 15 diagonals) scipy's call overhead would dominate;
these loops have none.

The factorization and the inverse band run each column through one body whose bound,
for a column with a rod's full band below it (8 sub-diagonals, :data:`FULL`), is that
constant: compiled for a known trip count the body is unrolled (both 1.5x faster at 153
dofs), and its arithmetic, in the same order either way, gives the same bits. The body is
a closure over the arrays, not a function taking them: numba inlines a closure as it is,
where an inlined function's array arguments each cost an atomic reference count (an
increment and a decrement) at every call, per column here (the inverse band of 960 dofs
52 -> 32 us, the Cholesky 28 -> 23 us; same bits). (The solves gain nothing from a
constant bound: each row waits for the one before.)
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..stencil import XX_BANDWIDTH
from .leaf import leaf

#: The sub-diagonals of the band most systems have (a rod's: its joints couple three
#: vertices): columns with that many below them run with it as a constant bound.
FULL = XX_BANDWIDTH


@leaf
def cholesky_into(ab, lt):
    """Cholesky factor of the symmetric positive definite matrix with lower band ab
    (b + 1, n), into lt (n, b + 1), lt[j, d] = L[j + d, j] with A = L L^T. Right-looking:
    each column, once divided by its pivot, updates the window below it. Raises
    ValueError if A is not positive definite (or not finite)."""
    if not cholesky_ok(ab, lt):
        raise ValueError("matrix is not positive definite")


@leaf
def cholesky_ok(ab, lt):
    """:func:`cholesky_into` that returns False instead of raising (lt is then partial)."""
    bwp, n = ab.shape
    bw = bwp - 1

    def eliminate(j, inv, m):  # column j divided by its pivot (inv: 1 / pivot), the m below it updated
        for r in range(1, m + 1):
            lt[j, r] *= inv
        for s in range(1, m + 1):
            ls = lt[j, s]
            if ls != 0.0:
                for r in range(s, m + 1):
                    lt[j + s, r - s] -= lt[j, r] * ls

    for j in range(n):
        for d in range(bwp):
            lt[j, d] = ab[d, j]
    for j in range(n):
        pivot = lt[j, 0]
        if not pivot > 0.0:
            return False
        pivot = math.sqrt(pivot)
        lt[j, 0] = pivot
        m = min(bw, n - 1 - j)
        if m == FULL:
            eliminate(j, 1.0 / pivot, FULL)
        else:
            eliminate(j, 1.0 / pivot, m)
        for r in range(m + 1, bwp):
            lt[j, r] = 0.0
    return True


@leaf
def solve_into(lt, x, lo, hi):
    """Solve L L^T y = x in place on x[lo:hi] (1D), for the diagonal block [lo, hi) of a
    block-diagonal matrix (or the whole matrix: lo = 0, hi = n)."""
    bw = lt.shape[1] - 1
    for j in range(lo, hi):  # forward: L y = b
        xj = x[j] / lt[j, 0]
        x[j] = xj
        if xj != 0.0:
            for r in range(1, min(bw, hi - 1 - j) + 1):
                x[j + r] -= lt[j, r] * xj
    for j in range(hi - 1, lo - 1, -1):  # backward: L^T x = y
        acc = x[j]
        for r in range(1, min(bw, hi - 1 - j) + 1):
            acc -= lt[j, r] * x[j + r]
        x[j] = acc / lt[j, 0]


@leaf
def solve_columns(lt, xs, lo, hi, first):
    """Solve L L^T Y = X in place for the columns of xs (n, m) side by side, rows lo..hi
    (a diagonal block, or the whole matrix). first: the first row where X may be nonzero
    (the forward sweep starts there; its rows above stay zero)."""
    bw = lt.shape[1] - 1
    m = xs.shape[1]
    for j in range(max(lo, first), hi):
        inv = 1.0 / lt[j, 0]
        for c in range(m):
            xs[j, c] *= inv
        for r in range(1, min(bw, hi - 1 - j) + 1):
            t = lt[j, r]
            for c in range(m):
                xs[j + r, c] -= t * xs[j, c]
    for j in range(hi - 1, lo - 1, -1):
        for r in range(1, min(bw, hi - 1 - j) + 1):
            t = lt[j, r]
            for c in range(m):
                xs[j, c] -= t * xs[j + r, c]
        inv = 1.0 / lt[j, 0]
        for c in range(m):
            xs[j, c] *= inv


@nb.njit(cache=True)
def inverse_band(lt, rows):
    """The entries of A^-1 inside the lower band of ``rows`` rows, from A's factor lt
    (n, b + 1) (rows <= b + 1). Returns zb, zb[d, j] = (A^-1)[j + d, j], shape (rows, n).

    Takahashi's recurrence, from the last column to the first: with Lt = L / diag(L),
    Z_ij = -sum_k Lt_kj Z_ik (i > j), Z_jj = 1 / L_jj^2 - sum_k Lt_kj Z_kj, k in (j, j + b].
    """
    n = lt.shape[0]
    bw = lt.shape[1] - 1
    # Z inside the factor's full band, column-major like lt: zt[j, d] = Z[j + d, j].
    zt = np.zeros((n, bw + 1))
    scaled = np.empty(bw + 1)  # Lt's column j

    def column(j, kmax):  # column j of Z from the kmax columns after it
        ljj = lt[j, 0]
        for dk in range(1, kmax + 1):
            scaled[dk] = lt[j, dk] / ljj
        for di in range(kmax, 0, -1):
            i = j + di
            acc = 0.0
            # Z_ik, i = j + di, k = j + dk: below the diagonal at zt[i, dk - di] when
            # dk >= di, else at zt[k, di - dk] (Z is symmetric; |i - k| < b).
            for dk in range(1, di):
                acc += scaled[dk] * zt[j + dk, di - dk]
            for dk in range(di, kmax + 1):
                acc += scaled[dk] * zt[i, dk - di]
            zt[j, di] = -acc
        acc = 0.0
        for dk in range(1, kmax + 1):
            acc += scaled[dk] * zt[j, dk]
        zt[j, 0] = 1.0 / (ljj * ljj) - acc

    for j in range(n - 1, -1, -1):
        kmax = min(bw, n - 1 - j)
        if kmax == FULL:
            column(j, FULL)
        else:
            column(j, kmax)
    zb = np.zeros((rows, n))
    for d in range(min(rows, bw + 1)):
        for j in range(n):
            zb[d, j] = zt[j, d]
    return zb


@leaf
def matvec_into(ab, w, y):
    """y = A w for symmetric A in lower banded form (b + 1, n); w, y shape (n,)."""
    bw = ab.shape[0] - 1
    n = ab.shape[1]
    for i in range(n):
        y[i] = ab[0, i] * w[i]
    for d in range(1, bw + 1):
        for j in range(n - d):
            y[j + d] += ab[d, j] * w[j]
            y[j] += ab[d, j] * w[j + d]
