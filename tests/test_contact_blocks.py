"""The contact rows' blocks (derods._numba.contact_blocks.partition) against a plain
reference: rods bound by rows are scipy's connected components of the rod graph the rows
draw, and each block holds exactly its rods' dofs, rows and nonzeros, in order."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from derods._numba.contact_blocks import partition


def random_rows(rng, n_rods, nefc):
    """Nonzeros (row, col) of nefc rows over n_rods rods of 3..12 dofs each, laid out
    among MuJoCo dofs with some dofs of no rod (a body's) between them; rows in
    nondecreasing order, as efc_triplets gives them. Returns (row, col, local_of_dof, dof_off)."""
    sizes = rng.integers(3, 13, n_rods)
    dof_off = np.concatenate([[0], np.cumsum(sizes)])
    n = dof_off[-1]
    nv = n + 7
    mujoco_dof = np.sort(rng.choice(nv, n, replace=False))
    local_of_dof = np.full(nv, -1, dtype=np.int64)
    local_of_dof[mujoco_dof] = np.arange(n)
    row, col = [], []
    for r in range(nefc):
        kind = rng.random()
        if kind < 0.15:  # a row on a body only
            cols = rng.choice(np.flatnonzero(local_of_dof < 0), 2, replace=False)
        else:
            rods = rng.choice(n_rods, 1 if kind < 0.7 else 2, replace=False)
            cols = np.concatenate([mujoco_dof[rng.integers(dof_off[k], dof_off[k + 1], 3)] for k in rods])
            if rng.random() < 0.2:  # and a body's dof
                cols = np.append(cols, np.flatnonzero(local_of_dof < 0)[0])
        cols = np.unique(cols)
        row += [r] * len(cols)
        col += list(cols)
    return np.array(row, dtype=np.int64), np.array(col, dtype=np.int64), local_of_dof, dof_off.astype(np.int64)


@pytest.mark.parametrize("seed", range(8))
def test_blocks_are_the_connected_rods_with_their_rows_and_nonzeros(seed):
    rng = np.random.default_rng(seed)
    n_rods, nefc = int(rng.integers(1, 9)), int(rng.integers(1, 40))
    row, col, local_of_dof, dof_off = random_rows(rng, n_rods, nefc)
    n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod = partition(
        row, col, nefc, local_of_dof, dof_off)

    # Reference: rods a row touches are joined; touched rods' components are the blocks.
    rod_of_local = np.searchsorted(dof_off, np.arange(dof_off[-1]), side="right") - 1
    loc = local_of_dof[col]
    on_rod = loc >= 0
    rod_of_nz = np.where(on_rod, rod_of_local[np.maximum(loc, 0)], -1)
    edges = [(rod_of_nz[p], rod_of_nz[q]) for p in range(len(row)) for q in range(len(row))
             if row[p] == row[q] and on_rod[p] and on_rod[q]]
    a, b = np.array(edges, dtype=np.int64).reshape(-1, 2).T
    _, label = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n_rods, n_rods)), directed=False)
    touched = np.zeros(n_rods, dtype=bool)
    touched[rod_of_nz[on_rod]] = True
    assert n_blocks == len(np.unique(label[touched]))
    for k in range(n_rods):
        assert (block_of_rod[k] >= 0) == touched[k]
        for j in range(n_rods):
            if touched[k] and touched[j]:
                assert (block_of_rod[k] == block_of_rod[j]) == (label[k] == label[j])

    for blk in range(n_blocks):
        # Dofs: the block's rods' dofs, ascending, with their places in the block.
        dofs = idx[start[blk]:start[blk + 1]]
        want = np.concatenate([np.arange(dof_off[k], dof_off[k + 1]) for k in np.flatnonzero(block_of_rod == blk)])
        np.testing.assert_array_equal(dofs, want)
        np.testing.assert_array_equal(compact[dofs], np.arange(len(dofs)))
        # Rows: those touching the block's rods, ascending, numbered within the block.
        mine = rows[row_start[blk]:row_start[blk + 1]]
        want_rows = np.unique(row[on_rod & (block_of_rod[np.maximum(rod_of_nz, 0)] == blk)])
        np.testing.assert_array_equal(mine, want_rows)
        np.testing.assert_array_equal(row_in_block[mine], np.arange(len(mine)))
        # Nonzeros: every entry of those rows (a body's too), in their order in the triplets.
        np.testing.assert_array_equal(nz[nz_start[blk]:nz_start[blk + 1]], np.flatnonzero(np.isin(row, mine)))
    assert np.all(compact[np.setdiff1d(np.arange(dof_off[-1]), idx)] == -1)
    assert np.all(row_in_block[np.setdiff1d(np.arange(nefc), rows)] == -1)


def test_no_row_on_a_rod_makes_no_block():
    local_of_dof = np.array([-1, 0, 1, 2, -1], dtype=np.int64)
    out = partition(np.array([0, 0], dtype=np.int64), np.array([0, 4], dtype=np.int64), 1, local_of_dof,
                    np.array([0, 3], dtype=np.int64))
    assert out[0] == 0
