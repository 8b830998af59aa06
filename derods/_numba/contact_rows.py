"""Constraint rows of MuJoCo's contacts on rod dofs, compiled: their products and line search.

A row that touches only neighbouring vertices of one rod fits a window of a few
dofs (a "banded" row: first dof ``col0`` and entries ``jw``); other rows touch
distant dofs ("far" rows, dense over the local dofs, or as CSR: ``fptr``, ``fcol``,
``fval``). MuJoCo's rows are read and sorted into these by :mod:`derods._numba.row_split`;
see :mod:`derods.sim.contact` for the problem they enter.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ..stencil import XX_BANDWIDTH
from .leaf import leaf

#: The window of a banded row in the usual band (a rod's: 8 sub-diagonals): rows whose
#: window lies whole within the dofs run with it as a constant bound, so that their loops
#: compile unrolled (the same arithmetic in the same order as any other bound).
WINDOW = XX_BANDWIDTH + 1


#: Far rows beyond which a contact solve without a border (:mod:`derods._numba.contact`)
#: stops treating them as a dense block: their weights row by row, Newton's direction by
#: conjugate gradients preconditioned with the band (:mod:`derods._numba.contact_newton`).
#: Below it, Woodbury's small dense system is exact and cheap (a knot's self-contact).
FAR_DENSE_MAX = 64


class Rows(NamedTuple):
    """Constraint rows over n local dofs: k_b banded rows, row i confined to the window
    [col0_i, col0_i + W) with entries jw_i (col0 (k_b,), jw (k_b, W)), then k_f far rows
    as CSR (fptr (k_f + 1,), fcol, fval)."""

    col0: np.ndarray
    jw: np.ndarray
    fptr: np.ndarray
    fcol: np.ndarray
    fval: np.ndarray


@nb.njit(cache=True)
def rows_band(col0, jw, weights, n):
    """Lower band (W, n) of sum_i w_i j_i j_i^T for rows j_i confined to windows
    [col0_i, col0_i + W) with entries jw_i (W = jw.shape[1])."""
    out = np.empty((jw.shape[1], n))
    rows_band_into(col0, jw, weights, out)
    return out


@leaf
def rows_band_into(col0, jw, weights, out):
    """:func:`rows_band` into out (W, n)."""
    out[:] = 0.0
    w_, n = out.shape

    def add(i, c0, wi, top):  # out += w_i j_i j_i^T (lower band), row i's first top entries
        for q in range(top):
            jq = jw[i, q] * wi
            if jq == 0.0:
                continue
            for p in range(q, top):
                out[p - q, c0 + q] += jw[i, p] * jq

    for i in range(len(col0)):
        wi = weights[i]
        if wi == 0.0:
            continue
        c0 = col0[i]
        top = min(w_, n - c0)  # the window's entries within the dofs
        if top == WINDOW:
            add(i, c0, wi, WINDOW)
        else:
            add(i, c0, wi, top)


@nb.njit(cache=True)
def rows_diag(col0, jw, zb):
    """j_i^T Z j_i for each windowed row, Z symmetric with lower band zb (>= W rows)."""
    w_ = jw.shape[1]
    n = zb.shape[1]
    out = np.zeros(len(col0))

    def quadratic(i, c0, top):  # j_i^T Z j_i over row i's first top entries
        acc = 0.0
        for q in range(top):
            jq = jw[i, q]
            if jq == 0.0:
                continue
            acc += jq * jq * zb[0, c0 + q]
            for p in range(q + 1, top):
                acc += 2.0 * jw[i, p] * jq * zb[p - q, c0 + q]
        return acc

    for i in range(len(col0)):
        c0 = col0[i]
        top = min(w_, n - c0)
        if top == WINDOW:
            out[i] = quadratic(i, c0, WINDOW)
        else:
            out[i] = quadratic(i, c0, top)
    return out


@nb.njit(cache=True)
def rows_apply(col0, jw, a):
    """J a for rows confined to windows [col0_i, col0_i + W) with entries jw_i; shape (k,)."""
    out = np.empty(len(col0))
    rows_apply_into(col0, jw, a, out)
    return out


@leaf
def rows_apply_into(col0, jw, a, out):
    """:func:`rows_apply` into out[:k] (k rows)."""
    n = a.shape[0]

    def dot(i, c0, top):  # j_i . a over row i's first top entries
        acc = 0.0
        for q in range(top):
            acc += jw[i, q] * a[c0 + q]
        return acc

    for i in range(len(col0)):
        c0 = col0[i]
        top = min(jw.shape[1], n - c0)
        if top == WINDOW:
            out[i] = dot(i, c0, WINDOW)
        else:
            out[i] = dot(i, c0, top)


@nb.njit(cache=True)
def rows_transpose_apply(col0, jw, lam, n):
    """J^T lam for windowed rows (as :func:`rows_apply`); shape (n,)."""
    out = np.empty(n)
    rows_transpose_apply_into(col0, jw, lam, out)
    return out


@leaf
def rows_transpose_apply_into(col0, jw, lam, out):
    """:func:`rows_transpose_apply` into out (n,)."""
    out[:] = 0.0
    n = out.shape[0]

    def add(li, i, c0, top):  # out += lam_i j_i over row i's first top entries
        for q in range(top):
            out[c0 + q] += jw[i, q] * li

    for i in range(len(col0)):
        c0 = col0[i]
        top = min(jw.shape[1], n - c0)
        if top == WINDOW:
            add(lam[i], i, c0, WINDOW)
        else:
            add(lam[i], i, c0, top)


@leaf
def exact_line_search(jar, jd, d, d_a, d_g, max_iter=20):
    """Step t minimizing f(t) = t^2 d_a / 2 + t d_g + sum_i d_i min(jar_i + t jd_i, 0)^2 / 2
    by Newton's method on the piecewise linear, increasing f'(t), from t = 1."""
    t = 1.0
    for _ in range(max_iter):
        fp = t * d_a + d_g
        fpp = d_a
        for i in range(len(jar)):
            r = jar[i] + t * jd[i]
            if r < 0.0:
                fp += d[i] * r * jd[i]
                fpp += d[i] * jd[i] * jd[i]
        step = fp / fpp
        t -= step
        if abs(step) <= 1e-12 * max(1.0, abs(t)):
            break
    return t


@nb.njit(cache=True)
def far_rows_csr(jf):
    """Far rows (k_f, n), dense, as CSR: (fptr (k_f + 1,), fcol, fval)."""
    k, n = jf.shape
    fptr = np.zeros(k + 1, dtype=np.int64)
    for r in range(k):
        c = 0
        for j in range(n):
            if jf[r, j] != 0.0:
                c += 1
        fptr[r + 1] = fptr[r] + c
    fcol = np.empty(fptr[k], dtype=np.int64)
    fval = np.empty(fptr[k])
    q = 0
    for r in range(k):
        for j in range(n):
            if jf[r, j] != 0.0:
                fcol[q] = j
                fval[q] = jf[r, j]
                q += 1
    return fptr, fcol, fval


@nb.njit(cache=True)
def apply_all(rows, a):
    """J a over the banded rows (first) and the far rows (:class:`Rows`), shape (k_b + k_f,)."""
    out = np.empty(len(rows.col0) + len(rows.fptr) - 1)
    apply_all_into(rows, a, out)
    return out


@leaf
def apply_all_into(rows, a, out):
    """:func:`apply_all` into out (k_b + k_f,)."""
    col0, jw, fptr, fcol, fval = rows
    kb = len(col0)
    rows_apply_into(col0, jw, a, out)
    for r in range(len(fptr) - 1):
        acc = 0.0
        for q in range(fptr[r], fptr[r + 1]):
            acc += fval[q] * a[fcol[q]]
        out[kb + r] = acc


@nb.njit(cache=True)
def transpose_apply_all(rows, lam, n):
    """J^T lam over the banded and the far rows (:class:`Rows`), shape (n,)."""
    out = np.empty(n)
    transpose_apply_all_into(rows, lam, out)
    return out


@leaf
def transpose_apply_all_into(rows, lam, out):
    """:func:`transpose_apply_all` into out (n,)."""
    col0, jw, fptr, fcol, fval = rows
    kb = len(col0)
    rows_transpose_apply_into(col0, jw, lam, out)
    for r in range(len(fptr) - 1):
        lr = lam[kb + r]
        if lr != 0.0:
            for q in range(fptr[r], fptr[r + 1]):
                out[fcol[q]] += fval[q] * lr


@nb.njit(cache=True)
def far_columns(rows, n):
    """The far rows' transposes (of :class:`Rows`) side by side, (n, k_f), and their first
    nonzero dof."""
    fptr, fcol, fval = rows.fptr, rows.fcol, rows.fval
    kf = len(fptr) - 1
    cols = np.zeros((n, kf))
    first = n
    for r in range(kf):
        for q in range(fptr[r], fptr[r + 1]):
            cols[fcol[q], r] = fval[q]
            first = min(first, fcol[q])
    return cols, first
