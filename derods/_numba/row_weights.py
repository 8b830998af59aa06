"""The contact rows' weights in the metric of the implicit step, compiled: MuJoCo's
impedance kept, its Delassus diagonal diag(J A^-1 J^T) taken in derods' A (band, twist
terms, and the border of bodies holding rods) instead of MuJoCo's M (step 2 of
:func:`derods._numba.contact.solve_block`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import inverse_band, solve_columns
from .cones import cone_weights
from .contact_rows import FAR_DENSE_MAX, apply_all, far_columns, rows_apply, rows_diag
from .dense import inverse_quadratic_rows
from .implicit import sm_solve_into


@nb.njit(cache=True)
def delassus_diagonal(system, rows, rod_of_dof):
    """diag(J A^-1 J^T) of every row (:class:`derods._numba.contact_rows.Rows`; A factored,
    :class:`derods._numba.implicit.System`): banded rows from the band of B^-1 (Takahashi)
    with the twist terms' Sherman-Morrison corrections; far rows by solves, side by side,
    or, past FAR_DENSE_MAX of them with rod_of_dof (n,) given (each dof's rod; empty:
    never), row by row (:func:`_far_diagonal`)."""
    lt, g, z, den, s = system.lt, system.g, system.z, system.den, system.weights[1]
    tw_lo, tw_hi, tw_c = system.tw_lo, system.tw_hi, system.tw_c
    col0, jw, fptr, fcol, fval = rows
    n = lt.shape[0]
    zb = inverse_band(lt, jw.shape[1])
    diag_b = rows_diag(col0, jw, zb)
    for i in range(len(tw_lo)):
        zi = np.zeros(n)
        lo, hi = tw_lo[i], tw_hi[i]
        for j in range(lo, hi):
            zi[j] = z[j]
        wi = s * tw_c[i] / den[i]
        jz = rows_apply(col0, jw, zi)
        for r in range(len(col0)):
            diag_b[r] -= wi * jz[r] * jz[r]
    kb = len(col0)
    kf = len(fptr) - 1
    out = np.empty(kb + kf)
    out[:kb] = diag_b
    if kf > FAR_DENSE_MAX and len(rod_of_dof) == n:
        _far_diagonal(system, rows, zb, rod_of_dof, out[kb:])
    elif kf:
        cols, first = far_columns(rows, n)
        solve_columns(lt, cols, 0, n, first)
        for i in range(len(tw_lo)):  # A^-1 = B^-1 - w z z^T for each twist term
            lo, hi = tw_lo[i], tw_hi[i]
            wi = s * tw_c[i] / den[i]
            for r in range(kf):
                gx = 0.0
                for j in range(lo, hi):
                    gx += g[j] * cols[j, r]
                for j in range(lo, hi):
                    cols[j, r] -= z[j] * wi * gx
        for r in range(kf):
            acc = 0.0
            for q in range(fptr[r], fptr[r + 1]):
                acc += fval[q] * cols[fcol[q], r]
            out[kb + r] = acc
    return out


@nb.njit(cache=True)
def _far_diagonal(system, rows, zb, rod_of_dof, out):
    """diag(J A^-1 J^T) of the far rows of ``rows`` into out (k_f,), each from its own
    dozen entries: A is block diagonal by rod (rod_of_dof (n,)), so a rod-rod row's parts
    on two rods do not meet in A^-1, and each part, one edge's vertices, lies inside the
    band of A^-1 that zb (:func:`derods._numba.banded.inverse_band`) holds; the twist terms
    subtract w_i (J z_i)^2. A row whose part on one rod spans more than that band (a
    rod touching itself far along) is solved for, alone: no (n, k_f) block of columns."""
    lt, z, den, s = system.lt, system.z, system.den, system.weights[1]
    tw_lo, tw_hi, tw_c = system.tw_lo, system.tw_hi, system.tw_c
    fptr, fcol, fval = rows.fptr, rows.fcol, rows.fval
    n = lt.shape[0]
    reach = min(zb.shape[0], lt.shape[1])
    tw_of = np.full(n, -1, dtype=np.int64)
    for i in range(len(tw_lo)):
        for j in range(tw_lo[i], tw_hi[i]):
            tw_of[j] = i
    col = np.zeros(n)
    for r in range(len(fptr) - 1):
        lo, hi = fptr[r], fptr[r + 1]
        local = True
        acc = 0.0
        for a in range(lo, hi):  # columns ascending within a row
            ca, va = fcol[a], fval[a]
            acc += va * va * zb[0, ca]
            for b in range(a + 1, hi):
                if rod_of_dof[fcol[b]] != rod_of_dof[ca]:
                    continue
                dd = fcol[b] - ca
                if dd >= reach:
                    local = False
                    break
                acc += 2.0 * va * fval[b] * zb[dd, ca]
            if not local:
                break
        if local:
            for a in range(lo, hi):
                t = tw_of[fcol[a]]
                first = t >= 0
                for b in range(lo, a):
                    if tw_of[fcol[b]] == t:
                        first = False
                if not first:
                    continue
                jz = 0.0
                for b in range(a, hi):
                    if tw_of[fcol[b]] == t:
                        jz += fval[b] * z[fcol[b]]
                acc -= s * tw_c[t] / den[t] * jz * jz
            out[r] = acc
            continue
        col[:] = 0.0
        for a in range(lo, hi):
            col[fcol[a]] = fval[a]
        sm_solve_into(system, col)  # A^-1 J^T, twist terms included
        acc = 0.0
        for a in range(lo, hi):
            acc += fval[a] * col[fcol[a]]
        out[r] = acc


@nb.njit(cache=True)
def row_weights(system, rows, y_border, jq, lu, piv, ratio, rod_of_dof, cones):
    """The rows' weights in the metric of the implicit step, MuJoCo's impedance kept: D_i =
    1 / (ratio_i diag(J H^-1 J^T)_i), 0 where that is not positive (a row nothing can
    move), an elliptic cone's frictional rows coupled to its normal row's as MuJoCo couples
    them (cones: :class:`derods._numba.cones.Cones`, :func:`derods._numba.cones.cone_weights`);
    H the rods' A, bordered by m dofs (bodies holding rods, :mod:`derods.sim.coupled`;
    m = 0 for none). diag(J H^-1 J^T) is the band's part
    (:func:`delassus_diagonal`) plus the border's, u S^-1 u^T with u = J_q - J_f y_border;
    y_border (n, m): A^-1 H_fq; jq (k, m): the rows' entries on the border; lu, piv: the
    Schur complement S's factors (:func:`derods._numba.dense.lu_factor`); ratio (k,):
    MuJoCo's R / diagA per row (its impedance); rod_of_dof (n,): each dof's rod, or empty
    (:func:`delassus_diagonal`). system: A, factored
    (:class:`derods._numba.implicit.System`); rows: J (:class:`derods._numba.contact_rows.Rows`)."""
    diag = delassus_diagonal(system, rows, rod_of_dof)
    k, m = jq.shape
    if m:
        u = jq.copy()
        col = np.empty(y_border.shape[0])
        for j in range(m):
            col[:] = y_border[:, j]
            ju = apply_all(rows, col)
            for i in range(k):
                u[i, j] -= ju[i]
        diag += inverse_quadratic_rows(lu, piv, u)
    w = np.zeros(k)
    for i in range(k):
        scaled = ratio[i] * diag[i]
        if scaled > 0.0:
            w[i] = 1.0 / scaled
    cone_weights(w, cones)
    return w
