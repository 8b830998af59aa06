"""Banded symmetric linear algebra, compiled: Cholesky, solves, products, inverse band.

Matrices are kept as their lower band, ``ab[d, j] = A[j + d, j]`` (the layout of
:func:`scipy.linalg.cholesky_banded` with ``lower=True``). At the sizes of one
rod (tens to hundreds of dofs, 9 to 15 diagonals) the call overhead of scipy
dominates; these loops have none.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def banded_inverse_band(lb):
    """The entries of A^-1 inside the band of A, from A's lower banded Cholesky factor.

    lb: lower band of L with A = L L^T (scipy.linalg.cholesky_banded(..., lower=True)),
    shape (b + 1, n). Returns zb with zb[d, j] = (A^-1)[j + d, j], shape (b + 1, n).
    Takahashi's recurrence, from the last column to the first: with Lt = L / diag(L),
    Z_ij = -sum_k Lt_kj Z_ik (i > j), Z_jj = 1 / L_jj^2 - sum_k Lt_kj Z_kj, k in (j, j + b].
    """
    bw = lb.shape[0] - 1
    n = lb.shape[1]
    zb = np.zeros_like(lb)
    for j in range(n - 1, -1, -1):
        ljj = lb[0, j]
        kmax = min(bw, n - 1 - j)
        for di in range(kmax, 0, -1):
            i = j + di
            acc = 0.0
            for dk in range(1, kmax + 1):
                k = j + dk
                # Z_ik with i, k > j, |i - k| < bw: stored at zb[|i - k|, min(i, k)].
                zik = zb[i - k, k] if i >= k else zb[k - i, i]
                acc += lb[dk, j] / ljj * zik
            zb[di, j] = -acc
        acc = 0.0
        for dk in range(1, kmax + 1):
            acc += lb[dk, j] / ljj * zb[dk, j]
        zb[0, j] = 1.0 / (ljj * ljj) - acc
    return zb


@nb.njit(cache=True)
def cholesky_into(ab, lb):
    """Lower banded Cholesky factor of a symmetric positive definite matrix, into lb.

    ab: lower band, ab[d, j] = A[j + d, j], shape (b + 1, n); lb: the factor L with
    A = L L^T in the same layout (what scipy.linalg.cholesky_banded(lower=True)
    returns), same shape, overwritten. Raises ValueError if A is not positive definite.
    """
    bw = ab.shape[0] - 1
    n = ab.shape[1]
    for j in range(n):
        acc = ab[0, j]
        for k in range(max(0, j - bw), j):
            ljk = lb[j - k, k]
            acc -= ljk * ljk
        if not acc > 0.0:
            raise ValueError("matrix is not positive definite")
        ljj = math.sqrt(acc)
        lb[0, j] = ljj
        for i in range(j + 1, min(n, j + bw + 1)):
            acc = ab[i - j, j]
            for k in range(max(0, i - bw), j):
                acc -= lb[i - k, k] * lb[j - k, k]
            lb[i - j, j] = acc / ljj
        for d in range(min(bw + 1, n - j), bw + 1):
            lb[d, j] = 0.0


@nb.njit(cache=True)
def band_cholesky(ab):
    """Lower banded Cholesky factor of ab (see :func:`cholesky_into`), a new array."""
    lb = np.zeros_like(ab)
    cholesky_into(ab, lb)
    return lb


@nb.njit(cache=True)
def solve_into(lb, x, lo, hi):
    """Solve L L^T y = x in place on x[lo:hi] (1D), for the diagonal block [lo, hi) of a
    block-diagonal matrix (or the whole matrix: lo = 0, hi = n)."""
    bw = lb.shape[0] - 1
    for j in range(lo, hi):  # forward: L y = b
        acc = x[j]
        for k in range(max(lo, j - bw), j):
            acc -= lb[j - k, k] * x[k]
        x[j] = acc / lb[0, j]
    for j in range(hi - 1, lo - 1, -1):  # backward: L^T x = y
        acc = x[j]
        for i in range(j + 1, min(hi, j + bw + 1)):
            acc -= lb[i - j, j] * x[i]
        x[j] = acc / lb[0, j]


@nb.njit(cache=True)
def band_solve(lb, rhs):
    """Solve L L^T x = rhs for a lower banded factor lb (b + 1, n); rhs shape (n, m)."""
    n, m = rhs.shape
    x = np.empty((m, n))
    for c in range(m):
        for j in range(n):
            x[c, j] = rhs[j, c]
        solve_into(lb, x[c], 0, n)
    return x.T.copy()


@nb.njit(cache=True)
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


@nb.njit(cache=True)
def band_matvec(ab, w):
    """y = A w for symmetric A in lower banded form (b + 1, n); w shape (n,)."""
    y = np.empty(ab.shape[1])
    matvec_into(ab, w, y)
    return y
