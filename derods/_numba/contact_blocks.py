"""Which of MuJoCo's constraint rows go with which rods: the rods a row touches are bound
together (union-find), and the rows, their Jacobian entries and the rods' dofs are laid
out block by block, so that the contact solve (:mod:`derods._numba.contact`) treats each
block of rods on its own. Rods are independent in the implicit system (its band is block
diagonal by rod); a row between two rods (rod-rod contact) joins their blocks."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@nb.njit(cache=True)
def partition(row, col, nefc, local_of_dof, dof_off):
    """Blocks of rods bound by rows, from the nonzeros (row, col) of MuJoCo's efc_J, row by
    row (row nondecreasing: :func:`derods._numba.row_split.efc_triplets`' order).

    local_of_dof (nv,): each MuJoCo dof's local rod dof or -1; dof_off (n_rods + 1,): each
    rod's local dofs. Returns (n_blocks; idx, the local dofs block by block, block b's at
    idx[start[b]:start[b + 1]]; compact (n,), a local dof's place in its block or -1;
    rows, the rows block by block at rows[row_start[b]:row_start[b + 1]]; row_in_block
    (nefc,), a row's number in its block or -1; nz, the nonzeros' indices block by block
    at nz[nz_start[b]:nz_start[b + 1]]; block_of_rod (n_rods,), -1 for a rod no row
    touches). n_blocks is 0 when no row touches a rod.
    """
    n = dof_off[-1]
    n_rods = len(dof_off) - 1
    # Rods bound together by rows (union-find over the rods each row touches).
    parent = np.arange(n_rods)
    rod_of_local = np.empty(n, dtype=np.int64)
    for rod in range(n_rods):
        rod_of_local[dof_off[rod]:dof_off[rod + 1]] = rod
    row_rod = np.full(nefc, -1)
    row_ptr = np.zeros(nefc + 1, dtype=np.int64)  # row r's nonzeros: row_ptr[r]:row_ptr[r + 1]
    for p in range(len(row)):
        row_ptr[row[p] + 1] += 1
        loc = local_of_dof[col[p]]
        if loc < 0:
            continue
        rod = rod_of_local[loc]
        r = row[p]
        if row_rod[r] < 0:
            row_rod[r] = rod
        elif row_rod[r] != rod:
            a, b = _root(parent, row_rod[r]), _root(parent, rod)
            if a != b:
                parent[max(a, b)] = min(a, b)
    touched = np.zeros(n_rods, dtype=np.bool_)
    for r in range(nefc):
        if row_rod[r] >= 0:
            touched[row_rod[r]] = True
    if not touched.any():
        none = np.zeros(0, dtype=np.int64)
        return 0, none, np.zeros(1, dtype=np.int64), none, none, none, none, none, none, none
    # Blocks: each root's rods in increasing order, their dofs laid end to end.
    block_of_root = np.full(n_rods, -1)
    n_blocks = 0
    for rod in range(n_rods):
        if touched[rod]:
            root = _root(parent, rod)
            if block_of_root[root] < 0:
                block_of_root[root] = n_blocks
                n_blocks += 1
    for rod in range(n_rods):  # rods joined to a touched rod through one with no row of its own
        root = _root(parent, rod)
        touched[rod] = block_of_root[root] >= 0
    block_of_rod = np.full(n_rods, -1)
    size = np.zeros(n_blocks + 1, dtype=np.int64)
    for rod in range(n_rods):
        if touched[rod]:
            block_of_rod[rod] = block_of_root[_root(parent, rod)]
            size[block_of_rod[rod] + 1] += dof_off[rod + 1] - dof_off[rod]
    start = np.cumsum(size)  # each block's slice of idx
    idx = np.empty(start[n_blocks], dtype=np.int64)  # local dofs, block by block
    compact = np.full(n, -1)  # a local dof's place in its block
    fill = start[:n_blocks].copy()
    for rod in range(n_rods):
        if touched[rod]:
            b = block_of_rod[rod]
            for j in range(dof_off[rod], dof_off[rod + 1]):
                compact[j] = fill[b] - start[b]
                idx[fill[b]] = j
                fill[b] += 1
    # Rows and Jacobian entries, block by block (counting sort).
    block_of_row = np.full(nefc, -1)
    n_rows = np.zeros(n_blocks + 1, dtype=np.int64)
    for r in range(nefc):
        if row_rod[r] >= 0:
            block_of_row[r] = block_of_rod[row_rod[r]]
            n_rows[block_of_row[r] + 1] += 1
    row_start = np.cumsum(n_rows)
    rows = np.empty(row_start[n_blocks], dtype=np.int64)
    row_in_block = np.full(nefc, -1)
    fill = row_start[:n_blocks].copy()
    for r in range(nefc):
        b = block_of_row[r]
        if b >= 0:
            row_in_block[r] = fill[b] - row_start[b]
            rows[fill[b]] = r
            fill[b] += 1
    for r in range(nefc):
        row_ptr[r + 1] += row_ptr[r]
    n_nz = np.zeros(n_blocks + 1, dtype=np.int64)
    for r in range(nefc):
        b = block_of_row[r]
        if b >= 0:
            n_nz[b + 1] += row_ptr[r + 1] - row_ptr[r]
    nz_start = np.cumsum(n_nz)
    nz = np.empty(nz_start[n_blocks], dtype=np.int64)
    q = 0
    for i in range(len(rows)):  # rows block by block, each row's nonzeros side by side
        for p in range(row_ptr[rows[i]], row_ptr[rows[i] + 1]):
            nz[q] = p
            q += 1
    return n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod
