"""The contact stage's blocks when every row belongs to one rod: each row of MuJoCo's
sparse Jacobian within one rod's band window (rods lying on or hitting the scene's
geometry, not each other, nor themselves far along, nor a body with dofs), sorted by rod
in one pass over the rows.

The general stage (:func:`derods._numba.contact.contact_step`) spreads MuJoCo's rows into
triplets, binds rods into blocks (:func:`derods._numba.contact_blocks.partition`),
renumbers each block's entries and splits its rows (:func:`derods._numba.row_split.split_rows`):
passes over every row and entry that, for ten rods lying on a floor (1280 rows), took ~60 of
the stage's ~300 us. When each row lies within one rod's window, the blocks are the rods the
rows touch and a row is one window: :func:`rods_own_rows` finds whether that holds and each
row's rod and first dof, :func:`rows_by_rod`, :func:`banded_rows` and :func:`range_system` give
each rod's rows, windows and system as the general stage would (the same rows in the same
order, the same windows, the same system: the same bits, ``tests/test_rod_blocks.py``), and
:func:`derods._numba.contact.contact_step` solves them.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .implicit import System


@nb.njit(cache=True)
def rods_own_rows(efc, supported_types, local_of_dof, dof_off, width):
    """Whether every row of ``efc`` (:class:`derods._numba.contact.Efc`, sparse) is of a
    supported type and has its stored entries on one rod's dofs, within a window of
    ``width`` (local_of_dof (nv,): each MuJoCo dof's local dof, -1 elsewhere; dof_off
    (n_rods + 1,)). Returns (that, rod (nefc,), lo (nefc,): each row's rod and first local
    dof; meaningful only when it holds)."""
    nefc = efc.nefc
    rod = np.empty(nefc, dtype=np.int64)
    lo = np.empty(nefc, dtype=np.int64)
    if not efc.is_sparse or nefc == 0:
        return False, rod, lo
    rownnz, rowadr, colind, efc_type = efc.rownnz, efc.rowadr, efc.colind, efc.type
    rod_of_local = np.empty(dof_off[-1], dtype=np.int64)
    for i in range(len(dof_off) - 1):
        rod_of_local[dof_off[i]:dof_off[i + 1]] = i
    for r in range(nefc):
        ok = False
        for q in range(len(supported_types)):
            ok |= efc_type[r] == supported_types[q]
        if not ok or rownnz[r] == 0:
            return False, rod, lo
        first, last = np.iinfo(np.int64).max, -1
        for p in range(rowadr[r], rowadr[r] + rownnz[r]):
            loc = local_of_dof[colind[p]]
            if loc < 0:
                return False, rod, lo
            first, last = min(first, loc), max(last, loc)
        if last - first >= width:
            return False, rod, lo
        i = rod_of_local[first]
        if last >= dof_off[i + 1]:  # on two rods
            return False, rod, lo
        rod[r], lo[r] = i, first
    return True, rod, lo


@nb.njit(cache=True)
def rows_by_rod(rod, n_rods):
    """The rows (rod (nefc,): each row's rod) rod by rod, MuJoCo's order within a rod:
    (start (n_rods + 1,), rows (nefc,)), rod i's rows at rows[start[i]:start[i + 1]]."""
    start = np.zeros(n_rods + 1, dtype=np.int64)
    for r in range(len(rod)):
        start[rod[r] + 1] += 1
    for i in range(n_rods):
        start[i + 1] += start[i]
    rows = np.empty(len(rod), dtype=np.int64)
    fill = start[:n_rods].copy()
    for r in range(len(rod)):
        rows[fill[rod[r]]] = r
        fill[rod[r]] += 1
    return start, rows


@nb.njit(cache=True)
def banded_rows(efc, efc_rows, lo, local_of_dof, d0, width):
    """A rod's rows efc_rows (k,) as banded rows over its dofs (the first at local dof d0):
    (col0 (k,), jw (k, width)), from MuJoCo's stored entries (lo (nefc,): each row's first
    local dof)."""
    k = len(efc_rows)
    rownnz, rowadr, colind, values = efc.rownnz, efc.rowadr, efc.colind, efc.j
    col0 = np.empty(k, dtype=np.int64)
    jw = np.zeros((k, width))
    for b in range(k):
        r = efc_rows[b]
        col0[b] = lo[r] - d0
        for p in range(rowadr[r], rowadr[r] + rownnz[r]):
            jw[b, local_of_dof[colind[p]] - lo[r]] = values[p]
    return col0, jw


@nb.njit(cache=True)
def range_system(system, d0, d1):
    """The implicit system (:class:`derods._numba.implicit.System`) of the rods whose dofs are
    d0 .. d1 - 1 (one rod, or rods in a row): copies of its part, the twist terms within it
    with their ranges from d0 (the system itself when the range is all of it). A block of
    the general stage whose dofs are a range takes it too (:func:`derods._numba.contact.solve_blocks`)."""
    if d1 - d0 == len(system.mass):
        return system
    tw_lo = system.tw_lo
    n_tw = 0
    for q in range(len(tw_lo)):
        if d0 <= tw_lo[q] < d1:
            n_tw += 1
    tw = np.empty(n_tw, dtype=np.int64)  # the rod's twist terms
    n_tw = 0
    for q in range(len(tw_lo)):
        if d0 <= tw_lo[q] < d1:
            tw[n_tw] = q
            n_tw += 1
    return System(system.k_band[:, d0:d1].copy(), system.mass[d0:d1].copy(), system.g[d0:d1].copy(),
                  system.tw_rod[tw], tw_lo[tw] - d0, system.tw_hi[tw] - d0, system.tw_c[tw],
                  system.a_band[:, d0:d1].copy(), system.lt[d0:d1].copy(), system.z[d0:d1].copy(), system.den[tw],
                  system.weights)
