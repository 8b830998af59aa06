"""Compiled mirror of :mod:`derods.sim.contact`: MuJoCo's contact problem re-solved in
the metric of the implicit step, from MuJoCo's rows to the corrected acceleration.

Each function follows the numbered steps of :mod:`derods.sim.contact`'s docstring;
the arrays of the implicit system are those of
:class:`derods.sim.implicit.ImplicitSystem` (band, factor, twist terms). Far rows
(rows that touch dofs too far apart for the band: self-contact, rod-rod contact)
are kept sparse, as CSR (``fptr``, ``fcol``, ``fval``). The Newton solve itself is
:mod:`derods._numba.contact_newton`; the rows' splitting, :mod:`derods._numba.row_split`;
their weights, :mod:`derods._numba.row_weights`; their products,
:mod:`derods._numba.contact_rows`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .cone_rows import block_cones, cone_groups, share_patterns
from .contact_blocks import partition
from .contact_newton import newton, no_border
from .contact_rows import Rows, transpose_apply_all
from .implicit import System, sm_solve_into
from .rod_blocks import banded_rows, range_system, rods_own_rows, rows_by_rod
from .row_split import efc_triplets, split_rows
from .row_weights import row_weights


class Efc(NamedTuple):
    """MuJoCo's constraint rows after its forward pass, as the contact stage reads them:
    is_sparse (efc_J in CSR: rownnz, rowadr, colind; else dense, nefc x nv row-major),
    nefc, nv; j (efc_J), type, force, aref, r (efc_R) and diag_a (efc_diagA) per row."""

    is_sparse: bool
    nefc: int
    nv: int
    j: np.ndarray
    rownnz: np.ndarray
    rowadr: np.ndarray
    colind: np.ndarray
    type: np.ndarray
    force: np.ndarray
    aref: np.ndarray
    r: np.ndarray
    diag_a: np.ndarray


@nb.njit(cache=True)
def contact_step(efc, cone_contacts, supported_types, local_of_dof, dof_off, width, system, a0, a_out, force_out,
                 max_iter, tol):
    """MuJoCo's constraint rows (``efc``, :class:`Efc`) on the rod dofs, re-solved in the
    implicit metric (``system``, A factored: :class:`derods._numba.implicit.System`);
    cone_contacts (:class:`derods._numba.cone_rows.ConeContacts`): MuJoCo's contacts, for the
    elliptic cones among the rows (empty if there are none).

    Rods are independent in A (its band is block diagonal by rod), so the rows are
    grouped into blocks of rods they bind together (one rod, or rods a rod-rod contact
    joins) and each block is solved on its own (:func:`solve_block`): a rod no row
    touches keeps a0 and costs nothing, and a block's Newton iterations and
    refactorizations stay its own. supported_types: the constraint types derods solves;
    local_of_dof (nv,): each MuJoCo dof's local dof, -1 elsewhere; dof_off (n_rods + 1,):
    each rod's local dof range; width: a banded row's window. Writes a_out (n,) [m/s^2]
    and force_out (n,) [N]. Returns 0 if no row touches a rod dof (nothing written), 1
    otherwise. When every row lies within one rod's window (no elliptic cones), the blocks
    are the rods, found in one pass (:mod:`derods._numba.rod_blocks`): the same blocks,
    rows and arithmetic as the general path, without its triplets, partition and splits.
    """
    if cone_contacts is None:  # no elliptic cones: maybe every row is one rod's (derods._numba.rod_blocks)
        own, rod, lo = rods_own_rows(efc, supported_types, local_of_dof, dof_off, width)
        if own:
            _solve_rods(efc, rod, lo, local_of_dof, dof_off, width, system, a0, a_out, force_out, max_iter, tol)
            return 1
    blocks = contact_blocks(efc, supported_types, local_of_dof, dof_off, system, a0, a_out, force_out)
    if blocks.n_blocks == 0:
        return 0
    solve_blocks(efc, cone_contacts, blocks, 0, blocks.n_blocks, local_of_dof, dof_off, width, system, a0, a_out,
                 force_out, max_iter, tol)
    return 1


@nb.njit(cache=True)
def _solve_rods(efc, rod, lo, local_of_dof, dof_off, width, system, a0, a_out, force_out, max_iter, tol):
    """:func:`contact_step` when each row lies within one rod's window (rod, lo (nefc,): each
    row's rod and first local dof, :func:`derods._numba.rod_blocks.rods_own_rows`): each rod
    the rows touch is a block of banded rows, solved as :func:`solve_block` would."""
    n_rods = len(dof_off) - 1
    start, rows = rows_by_rod(rod, n_rods)
    a_out[:] = a0
    force_out[:] = 0.0
    no_group = np.zeros(0, dtype=np.int64)
    no_far = (np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0))
    for i in range(n_rods):
        k = start[i + 1] - start[i]
        if k == 0:
            continue
        d0, d1 = dof_off[i], dof_off[i + 1]
        efc_rows = rows[start[i]:start[i + 1]]
        col0, jw = banded_rows(efc, efc_rows, lo, local_of_dof, d0, width)
        a_b = np.empty(d1 - d0)
        f_b = np.empty(d1 - d0)
        solve_split(np.arange(k), col0, jw, no_far, np.zeros(d1 - d0), efc, None, efc_rows, no_group,
                    range_system(system, d0, d1), np.full(d1 - d0, i), a0[d0:d1].copy(), a_b, f_b, max_iter, tol)
        a_out[d0:d1] = a_b
        force_out[d0:d1] = f_b


class Blocks(NamedTuple):
    """A step's rows grouped into blocks of rods (:func:`contact_blocks`): the nonzeros of
    MuJoCo's efc_J (row, col, val), the blocks (:func:`derods._numba.contact_blocks.partition`'s
    n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start,
    block_of_rod), which rows derods solves (supported (nefc,)) and each twist term's rod
    (rod_of_tw)."""

    row: np.ndarray
    col: np.ndarray
    val: np.ndarray
    n_blocks: int
    idx: np.ndarray
    start: np.ndarray
    compact: np.ndarray
    rows: np.ndarray
    row_start: np.ndarray
    row_in_block: np.ndarray
    nz: np.ndarray
    nz_start: np.ndarray
    block_of_rod: np.ndarray
    supported: np.ndarray
    rod_of_tw: np.ndarray


@nb.njit(cache=True)
def contact_blocks(efc, supported_types, local_of_dof, dof_off, system, a0, a_out, force_out):
    """The first half of :func:`contact_step`: MuJoCo's rows grouped into blocks of rods
    (:class:`Blocks`; n_blocks 0 when no row touches a rod, nothing written), and, when
    there are blocks, a_out = a0 and force_out = 0 for the blocks to write into."""
    nefc = efc.nefc
    tw_lo = system.tw_lo
    row, col, val = efc_triplets(efc.is_sparse, nefc, efc.nv, efc.j, efc.rownnz, efc.rowadr, efc.colind)
    n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod = partition(
        row, col, nefc, local_of_dof, dof_off)
    supported = np.zeros(nefc, dtype=np.bool_)
    rod_of_tw = np.empty(len(tw_lo), dtype=np.int64)
    if n_blocks:
        efc_type = efc.type
        for r in range(nefc):
            for q in range(len(supported_types)):
                if efc_type[r] == supported_types[q]:
                    supported[r] = True
        a_out[:] = a0
        force_out[:] = 0.0
        for i in range(len(tw_lo)):
            rod_of_tw[i] = np.searchsorted(dof_off, tw_lo[i], side="right") - 1
    return Blocks(row, col, val, n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start,
                  block_of_rod, supported, rod_of_tw)


@nb.njit(cache=True, nogil=True)
def solve_blocks(efc, cone_contacts, blocks, b0, b1, local_of_dof, dof_off, width, system, a0, a_out, force_out,
                 max_iter, tol):
    """The second half of :func:`contact_step`: blocks b0 .. b1 - 1 of ``blocks``
    (:class:`Blocks`) solved one by one (:func:`solve_block`) into a_out and force_out (their
    own dofs) and MuJoCo's efc_force (their own rows). Releases the GIL: two runs over
    disjoint ranges may share a step (:class:`derods.sim.contact.ContactStep`)."""
    row, col, val, _, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod, supported, \
        rod_of_tw = blocks
    tw_lo, tw_hi = system.tw_lo, system.tw_hi
    for b in range(b0, b1):
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
        lo = ids[0]
        if ids[m - 1] - lo == m - 1:  # a range of dofs (one rod, or rods in a row)
            block = range_system(system, lo, lo + m)
        else:
            n_tw = 0
            for q in range(len(rod_of_tw)):
                if block_of_rod[rod_of_tw[q]] == b:
                    n_tw += 1
            tw = np.empty(n_tw, dtype=np.int64)  # the block's twist terms
            n_tw = 0
            for q in range(len(rod_of_tw)):
                if block_of_rod[rod_of_tw[q]] == b:
                    tw[n_tw] = q
                    n_tw += 1
            tw_lo_b = np.empty(len(tw), dtype=np.int64)
            tw_hi_b = np.empty(len(tw), dtype=np.int64)
            for q in range(len(tw)):
                tw_lo_b[q] = compact[tw_lo[tw[q]]]
                tw_hi_b[q] = compact[tw_hi[tw[q]] - 1] + 1
            block = System(np.ascontiguousarray(system.k_band[:, ids]), system.mass[ids], system.g[ids],
                           system.tw_rod[tw], tw_lo_b, tw_hi_b, system.tw_c[tw],
                           np.ascontiguousarray(system.a_band[:, ids]), system.lt[ids], system.z[ids],
                           system.den[tw], system.weights)
        a_b = np.empty(m)
        f_b = np.empty(m)
        rod_b = np.empty(m, dtype=np.int64)  # each dof's rod (ids ascend: a walk along dof_off)
        rod = 0
        for q in range(m):
            while dof_off[rod + 1] <= ids[q]:
                rod += 1
            rod_b[q] = rod
        solve_block(row_b, col_b, val_b, efc, cone_contacts, block_rows, supported, local_b, width, block, rod_b,
                    a0[ids], a_b, f_b, max_iter, tol)
        for q in range(m):
            a_out[ids[q]] = a_b[q]
            force_out[ids[q]] = f_b[q]


@nb.njit(cache=True)
def solve_block(row, col, val, efc_data, cone_contacts, efc_rows, supported, local_of_dof, width, system, rod_of_dof,
                a0, a_out, force_out, max_iter, tol):
    """One block of rods' rows (k of them, with the nonzeros row, col, val; efc_rows (k,):
    their numbers among MuJoCo's rows ``efc_data``, :class:`Efc`; supported (nefc,): which of
    those derods solves) re-solved in the implicit metric (``system``, the block's A,
    factored: :class:`derods._numba.implicit.System`; rod_of_dof (n,): each dof's rod).

    1. Split the rows (:func:`split_rows`): derods solves the rows that touch only rod
       dofs and are of a supported type; the others keep MuJoCo's force (ext). An
       elliptic contact's rows (cone_contacts: :class:`derods._numba.cone_rows.ConeContacts`)
       are split as one, and solved as its cone (:mod:`derods._numba.cones`).
    2. Rescale the rows' weights D = 1 / R to the implicit metric, keeping MuJoCo's
       impedance: R = (R / diagA)_MuJoCo * diag(J A^-1 J^T); a cone's frictional rows
       take MuJoCo's coupling to its normal row's.
    3. From a0 + A^-1 ext, minimize MuJoCo's primal problem by Newton's method.
    Writes a_out (m,) [m/s^2] and force_out (m,) [N] (ext + J^T lam) on the block's dofs,
    and each solved row's force into ``efc_data.force`` (MuJoCo's efc_force, which
    mj_contactForce and the viewer read).
    """
    group = cone_groups(efc_rows, efc_data.type, cone_contacts)
    efc, _, col0, jw, far, ext = split_rows(row, col, val, local_of_dof, group, supported[efc_rows],
                                             efc_data.force[efc_rows], len(a0), width)
    solve_split(efc, col0, jw, far, ext, efc_data, cone_contacts, efc_rows, group, system, rod_of_dof, a0, a_out,
                force_out, max_iter, tol)


@nb.njit(cache=True)
def solve_split(efc, col0, jw, far, ext, efc_data, cone_contacts, efc_rows, group, system, rod_of_dof, a0, a_out,
                force_out, max_iter, tol):
    """Steps 2 and 3 of :func:`solve_block`, on a block's rows as step 1 splits them
    (:func:`derods._numba.row_split.split_rows`' efc, col0, jw, far and ext: its kb banded
    rows are col0's; group: :func:`derods._numba.cone_rows.cone_groups`'), into a_out,
    force_out and MuJoCo's efc_force."""
    n = len(a0)
    kb = len(col0)
    a = a0.copy()
    any_ext = False
    for j in range(n):
        if ext[j] != 0.0:
            any_ext = True
            break
    if any_ext:
        e = ext.copy()
        sm_solve_into(system, e)
        a += e
    force_out[:] = ext
    if len(efc):
        cones = block_cones(efc, efc_rows, efc_data.type, group, cone_contacts)
        fptr, fcol, fval = share_patterns(far[0], far[1], far[2], kb, cones) if len(cones.dim) else far
        rows = Rows(col0, jw, fptr, fcol, fval)
        aref = np.empty(len(efc))
        r_over_diag = np.empty(len(efc))
        for i in range(len(efc)):
            e = efc_rows[efc[i]]
            aref[i] = efc_data.aref[e]
            r_over_diag[i] = efc_data.r[e] / efc_data.diag_a[e]
        border = no_border(n, len(efc))  # none: also what row_weights takes for none
        d = row_weights(system, rows, border.h_fq, border.j_q, border.h_qq, np.zeros(0, dtype=np.int64), r_over_diag,
                        rod_of_dof, cones)
        if len(cones.dim):
            a, _, lam, _ = newton(system, a, rows, aref, d, border, cones, max_iter, tol)
        else:  # compiled without cones
            a, _, lam, _ = newton(system, a, rows, aref, d, border, None, max_iter, tol)
        force_out += transpose_apply_all(rows, lam, n)
        for i in range(len(efc)):  # derods' row forces, where MuJoCo's readers look for them
            efc_data.force[efc_rows[efc[i]]] = lam[i]
    a_out[:] = a
