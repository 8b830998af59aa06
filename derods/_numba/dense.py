"""Small dense systems, compiled: the few dofs of bodies that hold rods (a cart, an arm, a
box: m of 1 to ~20), solved many times a step. numpy's LAPACK calls cost ~10 us each in
call overhead at this size; these cost well under 1 us.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def spd_factor(a):
    """Cholesky factor of a small symmetric positive definite a (m, m), in place (lower
    part, the upper left as it was); returns False, a left half-factored, if a pivot is
    not positive (a is not positive definite)."""
    m = a.shape[0]
    for j in range(m):
        acc = a[j, j]
        for q in range(j):
            acc -= a[j, q] * a[j, q]
        if not acc > 0.0:
            return False
        ljj = np.sqrt(acc)
        a[j, j] = ljj
        for i in range(j + 1, m):
            acc = a[i, j]
            for q in range(j):
                acc -= a[i, q] * a[j, q]
            a[i, j] = acc / ljj
    return True


@nb.njit(cache=True)
def spd_solve_factored(a, b):
    """Solve L L^T x = b (m,) in place on b, L the factor :func:`spd_factor` left in a."""
    m = a.shape[0]
    for i in range(m):
        acc = b[i]
        for q in range(i):
            acc -= a[i, q] * b[q]
        b[i] = acc / a[i, i]
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for q in range(i + 1, m):
            acc -= a[q, i] * b[q]
        b[i] = acc / a[i, i]


@nb.njit(cache=True)
def lu_factor(a, piv):
    """LU factorization with partial pivoting of a small square a (m, m), in place (unit
    lower L below the diagonal, U on and above it); piv (m,) int64 receives the row swaps.
    For matrices that need not be symmetric (MuJoCo's M - h D with the implicit
    integrator's Coriolis derivatives)."""
    m = a.shape[0]
    for k in range(m):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, m):
            if abs(a[i, k]) > big:
                big, p = abs(a[i, k]), i
        piv[k] = p
        if p != k:
            for j in range(m):
                a[k, j], a[p, j] = a[p, j], a[k, j]
        pivot = a[k, k]
        for i in range(k + 1, m):
            a[i, k] /= pivot
            f = a[i, k]
            for j in range(k + 1, m):
                a[i, j] -= f * a[k, j]


@nb.njit(cache=True)
def lu_solve(a, piv, b):
    """Solve A x = b (m,) in place on b, with A's factors from :func:`lu_factor`."""
    m = a.shape[0]
    for k in range(m):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(m):
        acc = b[i]
        for q in range(i):
            acc -= a[i, q] * b[q]
        b[i] = acc
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for q in range(i + 1, m):
            acc -= a[i, q] * b[q]
        b[i] = acc / a[i, i]


@nb.njit(cache=True)
def inverse_quadratic_rows(a, piv, u):
    """diag(U A^-1 U^T) (k,) for U (k, m), A's factors from :func:`lu_factor`: each row's
    quadratic form in A^-1 (a constraint row's share of the Delassus diagonal through the
    border's Schur complement).

    Every row is solved as :func:`lu_solve` solves it, the same operations in the same
    order, but all rows at once, sweep by sweep: a call of lu_solve per row cost ~40 ns
    (4.6 us for a cart's 112 floor rows, m = 1), more than its arithmetic."""
    k, m = u.shape
    x = u.copy()
    for c in range(m):
        p = piv[c]
        if p != c:
            for i in range(k):
                x[i, c], x[i, p] = x[i, p], x[i, c]
    for c in range(m):
        for i in range(k):
            acc = x[i, c]
            for q in range(c):
                acc -= a[c, q] * x[i, q]
            x[i, c] = acc
    for c in range(m - 1, -1, -1):
        for i in range(k):
            acc = x[i, c]
            for q in range(c + 1, m):
                acc -= a[c, q] * x[i, q]
            x[i, c] = acc / a[c, c]
    out = np.empty(k)
    for i in range(k):
        acc = 0.0
        for j in range(m):
            acc += u[i, j] * x[i, j]
        out[i] = acc
    return out


@nb.njit(cache=True)
def sparse_block_into(values, rowadr, rownnz, colind, dofs, out):
    """out (k, k) <- the block on the sorted ``dofs`` (k,) of a symmetric matrix MuJoCo keeps
    as its lower triangle in CSR (``data.M`` with ``model.M_rowadr``, ``M_rownnz``,
    ``M_colind``: the mass matrix, whose off-diagonal entries join a dof to its ancestors)."""
    k = len(dofs)
    out[:] = 0.0
    for p in range(k):
        i = dofs[p]
        for e in range(rowadr[i], rowadr[i] + rownnz[i]):
            j = colind[e]
            q = np.searchsorted(dofs, j)
            if q < k and dofs[q] == j:
                out[p, q] = values[e]
                out[q, p] = values[e]


@nb.njit(cache=True)
def damped_block_into(values, rowadr, rownnz, colind, dofs, damping, h, out):
    """out (k, k) <- :func:`sparse_block_into`'s block of M on the sorted ``dofs`` (k,), its
    diagonal less h D with D = -damping[dofs] (damping (nv,) [N s/m or N m s]): the
    M - h D of MuJoCo's Euler integrator, which takes the joint damping implicitly."""
    sparse_block_into(values, rowadr, rownnz, colind, dofs, out)
    for p in range(len(dofs)):
        out[p, p] -= h * -damping[dofs[p]]
