"""Constraint rows of MuJoCo's contacts on rod dofs, compiled: splitting, products, line search.

A row that touches only neighbouring vertices of one rod fits a window of a few
dofs (a "banded" row: first dof ``col0`` and entries ``jw``); other rows touch
distant dofs ("far" rows, dense over the local dofs, or as CSR: ``fptr``, ``fcol``,
``fval``). See :mod:`derods.sim.contact` for the problem these rows enter.
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
def sparse_triplets(rownnz, rowadr, colind, values):
    """(row, col, value) of every nonzero of a CSR matrix (MuJoCo's sparse efc_J)."""
    total = 0
    for r in range(len(rownnz)):
        total += rownnz[r]
    row = np.empty(total, dtype=np.int64)
    col = np.empty(total, dtype=np.int64)
    val = np.empty(total)
    p = 0
    for r in range(len(rownnz)):
        for q in range(rownnz[r]):
            row[p] = r
            col[p] = colind[rowadr[r] + q]
            val[p] = values[rowadr[r] + q]
            p += 1
    return row, col, val


@nb.njit(cache=True)
def split_rows(row, col, val, local_of_dof, group, supported, force, n, width):
    """Sort constraint rows that touch rod dofs (step 1 of :func:`derods._numba.contact.contact_step`).

    row, col, val: the nonzeros of MuJoCo's efc_J; local_of_dof (nv,): local rod dof or -1;
    group (nefc,) or empty: rows split as one (:func:`split_bordered_rows`);
    supported (nefc,): rows derods can solve; force (nefc,): MuJoCo's row forces; n: local
    dofs; width: window of a banded row. A row is derods' if it touches only rod dofs and is
    supported; its force is MuJoCo's otherwise (returned as ext on the local dofs).
    Returns (efc: derods' rows, banded first; kb: how many are banded; col0 (kb,);
    jw (kb, width); far: the far rows as CSR (fptr, fcol, fval); ext (n,)).
    """
    no_border = np.full(len(local_of_dof), -1, dtype=np.int64)
    efc, kb, col0, jw, far, _, ext, _ = split_bordered_rows(row, col, val, local_of_dof, no_border, group, supported,
                                                            force, n, 0, width)
    return efc, kb, col0, jw, far, ext


@nb.njit(cache=True)
def split_bordered_rows(row, col, val, local_of_dof, border_of_dof, group, supported, force, n, m, width):
    """:func:`split_rows` over n local dofs bordered by m more (border_of_dof (nv,): each
    MuJoCo dof's place among them, -1 elsewhere; see :class:`derods._numba.contact_newton.Border`).
    group (nefc,) or empty: each row's group, the number of its first row (an elliptic
    cone's rows: :mod:`derods._numba.cones`); a group's rows are split alike, banded ones
    on one window.

    A row is derods' if it touches only local and border dofs (at least one) and is
    supported; a row that touches border dofs only is banded with an empty window.
    Returns (efc, kb, col0 (kb,), jw (kb, width), far, jq (k, m), ext (n,), ext_q (m,)):
    far the k - kb far rows as CSR (fptr, fcol, fval; as :func:`far_rows_csr` makes from
    them dense), ext and ext_q MuJoCo's force of the other rows on the local and border
    dofs.
    """
    nefc = len(supported)
    touches = np.zeros(nefc, dtype=np.bool_)
    elsewhere = np.zeros(nefc, dtype=np.bool_)
    lo = np.full(nefc, np.iinfo(np.int64).max)
    hi = np.full(nefc, -1)
    for p in range(len(row)):
        r = row[p]
        loc = local_of_dof[col[p]]
        if loc >= 0:
            touches[r] = True
            lo[r] = min(lo[r], loc)
            hi[r] = max(hi[r], loc)
        elif border_of_dof[col[p]] >= 0:
            touches[r] = True
        else:
            elsewhere[r] = True
    for r in range(len(group)):  # a group's rows as one: what any of them touches
        g = group[r]
        if g != r:
            touches[g] |= touches[r]
            elsewhere[g] |= elsewhere[r]
            lo[g] = min(lo[g], lo[r])
            hi[g] = max(hi[g], hi[r])
    for r in range(len(group)):
        g = group[r]
        touches[r], elsewhere[r], lo[r], hi[r] = touches[g], elsewhere[g], lo[g], hi[g]
    # Loops, not array expressions: each temporary array is an allocation, and this runs
    # once per block of rods every step.
    mine = np.empty(nefc, dtype=np.bool_)
    others = False  # rows that touch the dofs and keep MuJoCo's force
    for r in range(nefc):
        mine[r] = touches[r] and not elsewhere[r] and supported[r]
        others |= touches[r] and not mine[r]
    ext = np.zeros(n)
    ext_q = np.zeros(m)
    for p in range(len(row) if others else 0):
        r = row[p]
        loc = local_of_dof[col[p]]
        if loc >= 0 and touches[r] and not mine[r]:
            ext[loc] += val[p] * force[r]
        elif m and loc < 0 and touches[r] and not mine[r] and border_of_dof[col[p]] >= 0:
            ext_q[border_of_dof[col[p]]] += val[p] * force[r]
    kb, n_mine = 0, 0
    for r in range(nefc):
        if hi[r] < 0:  # border dofs only: an empty window at the start
            lo[r] = 0
        if mine[r]:
            n_mine += 1
            if hi[r] - lo[r] < width:
                kb += 1
    efc = np.empty(n_mine, dtype=np.int64)  # derods' rows: the banded ones, then the far ones
    q_b, q_f = 0, kb
    for r in range(nefc):
        if mine[r]:
            if hi[r] - lo[r] < width:
                efc[q_b] = r
                q_b += 1
            else:
                efc[q_f] = r
                q_f += 1
    k_of_row = np.full(nefc, -1)
    for k in range(len(efc)):
        k_of_row[efc[k]] = k
    jw = np.zeros((kb, width))
    jq = np.zeros((len(efc), m))
    kf = len(efc) - kb
    fptr = np.zeros(kf + 1, dtype=np.int64)
    for p in range(len(row)):
        k = k_of_row[row[p]]
        if k < 0:
            continue
        loc = local_of_dof[col[p]]
        if loc < 0:
            if m and border_of_dof[col[p]] >= 0:
                jq[k, border_of_dof[col[p]]] = val[p]
            continue
        if k < kb:
            jw[k, loc - lo[row[p]]] = val[p]
        elif val[p] != 0.0:
            fptr[k - kb + 1] += 1
    for r in range(kf):
        fptr[r + 1] += fptr[r]
    # The far rows as CSR straight from the nonzeros (never dense: a pile's thousands of
    # rod-rod rows over its thousands of dofs), each row's columns ascending.
    fcol = np.empty(fptr[kf], dtype=np.int64)
    fval = np.empty(fptr[kf])
    fill = fptr[:kf].copy()
    for p in range(len(row) if kf else 0):
        k = k_of_row[row[p]]
        if k < kb or val[p] == 0.0:
            continue
        loc = local_of_dof[col[p]]
        if loc < 0:
            continue
        q = fill[k - kb]
        while q > fptr[k - kb] and fcol[q - 1] > loc:  # insertion: rows have a dozen entries
            fcol[q] = fcol[q - 1]
            fval[q] = fval[q - 1]
            q -= 1
        fcol[q] = loc
        fval[q] = val[p]
        fill[k - kb] += 1
    col0 = np.empty(kb, dtype=np.int64)
    for k in range(kb):
        col0[k] = lo[efc[k]]
    return efc, kb, col0, jw, (fptr, fcol, fval), jq, ext, ext_q


@nb.njit(cache=True)
def efc_triplets(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind):
    """(row, col, value) of every nonzero of MuJoCo's constraint Jacobian efc_J, sparse
    (CSR: rownnz, rowadr, colind) or dense (nefc x nv, row-major)."""
    if is_sparse:
        return sparse_triplets(rownnz[:nefc], rowadr[:nefc], colind, efc_j)
    total = 0
    for p in range(nefc * nv):
        if efc_j[p] != 0.0:
            total += 1
    row = np.empty(total, dtype=np.int64)
    col = np.empty(total, dtype=np.int64)
    val = np.empty(total)
    q = 0
    for p in range(nefc * nv):
        if efc_j[p] != 0.0:
            row[q] = p // nv
            col[q] = p % nv
            val[q] = efc_j[p]
            q += 1
    return row, col, val


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

