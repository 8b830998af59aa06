"""Whether derods' contact solve takes every constraint row of a step (compiled: called
each step, :mod:`derods.sim.forward`)."""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def rods_solve_all(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind, efc_type, supported, solved_dof):
    """True if each of the nefc rows of MuJoCo's constraint Jacobian efc_J (sparse: CSR
    rownnz, rowadr, colind; dense: nefc x nv, row-major) is of a type in ``supported`` and
    has nonzeros only on dofs whose rows derods solves (solved_dof (nv,) bool)."""
    for r in range(nefc):
        ok = False
        for t in supported:
            if efc_type[r] == t:
                ok = True
        if not ok:
            return False
        if is_sparse:
            for p in range(rowadr[r], rowadr[r] + rownnz[r]):
                if efc_j[p] != 0.0 and not solved_dof[colind[p]]:
                    return False
        else:
            for c in range(nv):
                if efc_j[r * nv + c] != 0.0 and not solved_dof[c]:
                    return False
    return True


@nb.njit(cache=True)
def rows_touch_rods(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind, local_of_dof):
    """True if a row of MuJoCo's constraint Jacobian (as :func:`rods_solve_all` reads it)
    has an entry on a rod dof (local_of_dof (nv,) >= 0): exactly when the contact stage
    has rows to solve (:func:`derods._numba.contact.contact_step` reads the same entries:
    a sparse row's stored ones, a dense row's nonzeros)."""
    for r in range(nefc):
        if is_sparse:
            for p in range(rowadr[r], rowadr[r] + rownnz[r]):
                if local_of_dof[colind[p]] >= 0:
                    return True
        else:
            for c in range(nv):
                if efc_j[r * nv + c] != 0.0 and local_of_dof[c] >= 0:
                    return True
    return False
