"""MuJoCo's constraint rows read and sorted onto rod dofs, compiled: the nonzeros of its
efc_J as triplets, and a block's rows split into derods' banded and far rows (the forms of
:mod:`derods._numba.contact_rows`) and MuJoCo's force of the rows derods leaves to it.
"""

from __future__ import annotations

import numba as nb
import numpy as np


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
    far the k - kb far rows as CSR (fptr, fcol, fval; as :func:`derods._numba.contact_rows.far_rows_csr` makes from
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
