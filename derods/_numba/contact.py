"""Compiled mirror of :mod:`derods.sim.contact`: MuJoCo's contact problem re-solved in
the metric of the implicit step, from MuJoCo's rows to the corrected acceleration.

Each function follows the numbered steps of :mod:`derods.sim.contact`'s docstring;
the arrays of the implicit system are those of
:class:`derods.sim.implicit.ImplicitSystem` (band, factor, twist terms). Far rows
(rows that touch dofs too far apart for the band: self-contact, rod-rod contact)
are kept sparse, as CSR (``fptr``, ``fcol``, ``fval``). The Newton solve itself is
:mod:`derods._numba.contact_newton`; the rows' splitting and products,
:mod:`derods._numba.contact_rows`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import inverse_band, solve_columns
from .contact_blocks import partition
from .contact_newton import newton, no_border
from .dense import inverse_quadratic_rows
from .contact_rows import apply_all, efc_triplets, far_columns, far_rows_csr, rows_apply, rows_diag, split_rows
from .contact_rows import transpose_apply_all
from .implicit import sm_solve_into


@nb.njit(cache=True)
def delassus_diagonal(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol, fval):
    """diag(J A^-1 J^T) of every row: banded rows from the band of B^-1 (Takahashi) with
    the twist terms' Sherman-Morrison corrections; far rows by solves, side by side."""
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
    if kf:
        cols, first = far_columns(fptr, fcol, fval, n)
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
def row_weights(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol, fval, y_border, jq, lu, piv, ratio):
    """The rows' weights in the metric of the implicit step, MuJoCo's impedance kept: D_i =
    1 / (ratio_i diag(J H^-1 J^T)_i), 0 where that is not positive (a row nothing can
    move); H the rods' A, bordered by m dofs (bodies holding rods, :mod:`derods.sim.coupled`;
    m = 0 for none). diag(J H^-1 J^T) is the band's part
    (:func:`delassus_diagonal`) plus the border's, u S^-1 u^T with u = J_q - J_f y_border;
    y_border (n, m): A^-1 H_fq; jq (k, m): the rows' entries on the border; lu, piv: the
    Schur complement S's factors (:func:`derods._numba.dense.lu_factor`); ratio (k,):
    MuJoCo's R / diagA per row (its impedance)."""
    diag = delassus_diagonal(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol, fval)
    k, m = jq.shape
    if m:
        u = jq.copy()
        col = np.empty(y_border.shape[0])
        for j in range(m):
            col[:] = y_border[:, j]
            ju = apply_all(col0, jw, fptr, fcol, fval, col)
            for i in range(k):
                u[i, j] -= ju[i]
        diag += inverse_quadratic_rows(lu, piv, u)
    w = np.zeros(k)
    for i in range(k):
        scaled = ratio[i] * diag[i]
        if scaled > 0.0:
            w[i] = 1.0 / scaled
    return w


@nb.njit(cache=True)
def contact_step(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind, efc_type, efc_force, efc_aref, efc_r,
                 efc_diag_a, supported_types, local_of_dof, dof_off, width, k_band, a_band, lt, g, tw_lo, tw_hi,
                 tw_c, s, z, den, mass, m_coef, a0, a_out, force_out, max_iter, tol):
    """MuJoCo's constraint rows on the rod dofs, re-solved in the implicit metric.

    Rods are independent in A (its band is block diagonal by rod), so the rows are
    grouped into blocks of rods they bind together (one rod, or rods a rod-rod contact
    joins) and each block is solved on its own (:func:`solve_block`): a rod no row
    touches keeps a0 and costs nothing, and a block's Newton iterations and
    refactorizations stay its own. dof_off (n_rods + 1,): each rod's local dof range.
    Writes a_out (n,) [m/s^2] and force_out (n,) [N]. Returns 0 if no row touches a
    rod dof (nothing written), 1 otherwise.
    """
    row, col, val = efc_triplets(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind)
    n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod = partition(
        row, col, nefc, local_of_dof, dof_off)
    if n_blocks == 0:
        return 0
    supported = np.zeros(nefc, dtype=np.bool_)
    for r in range(nefc):
        for q in range(len(supported_types)):
            if efc_type[r] == supported_types[q]:
                supported[r] = True
    a_out[:] = a0
    force_out[:] = 0.0
    rod_of_tw = np.empty(len(tw_lo), dtype=np.int64)
    for i in range(len(tw_lo)):
        rod_of_tw[i] = np.searchsorted(dof_off, tw_lo[i], side="right") - 1
    for b in range(n_blocks):
        ids = idx[start[b]:start[b + 1]]
        m = len(ids)
        # The block's rows: row numbers within the block, columns in the block's dofs
        # (m: a dof of no rod, so that split_rows sees the row reach elsewhere).
        block_rows = rows[row_start[b]:row_start[b + 1]]
        ps = nz[nz_start[b]:nz_start[b + 1]]
        row_b = np.empty(len(ps), dtype=np.int64)
        col_b = np.empty(len(ps), dtype=np.int64)
        val_b = np.empty(len(ps))
        for q in range(len(ps)):
            p = ps[q]
            row_b[q] = row_in_block[row[p]]
            loc = local_of_dof[col[p]]
            col_b[q] = compact[loc] if loc >= 0 else m
            val_b[q] = val[p]
        local_b = np.arange(m + 1)
        local_b[m] = -1
        tw = np.flatnonzero(block_of_rod[rod_of_tw] == b)
        tw_lo_b = np.empty(len(tw), dtype=np.int64)
        tw_hi_b = np.empty(len(tw), dtype=np.int64)
        for q in range(len(tw)):
            tw_lo_b[q] = compact[tw_lo[tw[q]]]
            tw_hi_b[q] = compact[tw_hi[tw[q]] - 1] + 1
        a_b = np.empty(m)
        f_b = np.empty(m)
        solve_block(row_b, col_b, val_b, block_rows, supported[block_rows], efc_force[block_rows],
                    efc_aref[block_rows], efc_r[block_rows], efc_diag_a[block_rows], local_b, width,
                    np.ascontiguousarray(k_band[:, ids]), np.ascontiguousarray(a_band[:, ids]), lt[ids],
                    g[ids], tw_lo_b, tw_hi_b, tw_c[tw], s, z[ids], den[tw], mass[ids], m_coef, a0[ids], a_b, f_b,
                    max_iter, tol)
        for q in range(m):
            a_out[ids[q]] = a_b[q]
            force_out[ids[q]] = f_b[q]
    return 1


@nb.njit(cache=True)
def solve_block(row, col, val, efc_rows, supported, efc_force, efc_aref, efc_r, efc_diag_a, local_of_dof, width,
                k_band, a_band, lt, g, tw_lo, tw_hi, tw_c, s, z, den, mass, m_coef, a0, a_out, force_out, max_iter,
                tol):
    """One block of rods' rows (k of them, with the nonzeros row, col, val; efc_rows (k,):
    MuJoCo's numbers of the rows, for reference only) re-solved in the implicit metric.

    1. Split the rows (:func:`split_rows`): derods solves the rows that touch only rod
       dofs and are of a supported type; the others keep MuJoCo's force (ext).
    2. Rescale the rows' weights D = 1 / R to the implicit metric, keeping MuJoCo's
       impedance: R = (R / diagA)_MuJoCo * diag(J A^-1 J^T).
    3. From a0 + A^-1 ext, minimize MuJoCo's primal problem by Newton's method.
    Writes a_out (m,) [m/s^2] and force_out (m,) [N] (ext + J^T lam) on the block's dofs.
    """
    n = len(a0)
    efc, kb, col0, jw, jf, ext = split_rows(row, col, val, local_of_dof, supported, efc_force, n, width)
    a = a0.copy()
    any_ext = False
    for j in range(n):
        if ext[j] != 0.0:
            any_ext = True
            break
    if any_ext:
        e = ext.copy()
        sm_solve_into(lt, g, tw_lo, tw_hi, tw_c, s, z, den, e)
        a += e
    force_out[:] = ext
    if len(efc):
        fptr, fcol, fval = far_rows_csr(jf)
        aref = np.empty(len(efc))
        r_over_diag = np.empty(len(efc))
        for i in range(len(efc)):
            aref[i] = efc_aref[efc[i]]
            r_over_diag[i] = efc_r[efc[i]] / efc_diag_a[efc[i]]
        d = row_weights(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol, fval, np.zeros((n, 0)),
                        np.zeros((len(efc), 0)), np.zeros((0, 0)), np.zeros(0, dtype=np.int64), r_over_diag)
        a, _, lam, _ = newton(k_band, a_band, g, tw_lo, tw_hi, tw_c, s, mass, m_coef, a, col0, jw, fptr, fcol,
                              fval, aref, d, no_border(n, len(efc)), max_iter, tol)
        force_out += transpose_apply_all(col0, jw, fptr, fcol, fval, lam, n)
    a_out[:] = a
