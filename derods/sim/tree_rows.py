"""The rows that bind joined body trees among themselves (equalities, joint limits), solved
with the rods.

When body trees join the contact solve (:mod:`derods.sim.contact`: a gripper's fingers
pressing on a cable), the rows on their dofs alone are part of the same problem: a
finger equality that makes the second finger follow the first carries the squeeze to it.
Left with the force MuJoCo's own solve gave them, computed while that solve saw bare
vertex masses at the cable, they do not balance the forces derods finds (two jaws coupled
by an equality squeezing a cable: 3 mm apart from equal, the cable pushed 2 mm aside).

The solve takes one-sided rows (MuJoCo's primal cost 1/2 D min(J a - aref, 0)^2). A
joint-limit row is one. An equality row costs 1/2 D (J a - aref)^2, which is the sum of
two one-sided rows: itself and its negation (-J, -aref; the same D). So
:func:`solvable_rows` hands the compiled stage MuJoCo's rows with such rows labelled as
frictionless contact rows (the one-sided kind it solves) and each equality's negation
appended, and :meth:`SolvableRows.finish` writes each equality's force back as the
difference of its two halves (-D (J a - aref), MuJoCo's sign). Rows that touch a rod or a
dof outside the joined trees keep MuJoCo's force, as before.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from .._numba.contact import Efc
from .._numba.row_split import efc_triplets

_EQUALITY = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
_LIMIT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
_ONE_SIDED = int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS)


class SolvableRows(NamedTuple):
    """MuJoCo's rows as the compiled stage solves them (``efc``, an
    :class:`derods._numba.contact.Efc` of nefc + k rows, its force array its own) and the k
    equality rows ``doubled`` (MuJoCo's numbers) whose negations are rows nefc ... nefc + k."""

    efc: Efc
    doubled: np.ndarray

    def finish(self, data: mujoco.MjData) -> None:
        """The solved forces into MuJoCo's efc_force, each equality's two halves combined."""
        nefc = data.nefc
        force = self.efc.force
        data.efc_force[:nefc] = force[:nefc]
        data.efc_force[self.doubled] -= force[nefc:]


def solvable_rows(efc: Efc, data: mujoco.MjData, tree_dof: np.ndarray) -> SolvableRows | None:
    """``efc`` (MuJoCo's rows of ``data``) with the equality and joint-limit rows that touch
    only the dofs marked in ``tree_dof`` (nv,) bool (the joined trees') made solvable (see
    the module docstring); None if there are none."""
    nefc, nv = efc.nefc, efc.nv
    kind = efc.type[:nefc]
    candidate = (kind == _EQUALITY) | (kind == _LIMIT)
    if not candidate.any():
        return None
    row, col, _ = efc_triplets(efc.is_sparse, nefc, nv, efc.j, efc.rownnz, efc.rowadr, efc.colind)
    outside = np.zeros(nefc, dtype=bool)
    outside[row[~tree_dof[col]]] = True
    inside = np.zeros(nefc, dtype=bool)
    inside[row] = True
    take = candidate & inside & ~outside
    if not take.any():
        return None
    doubled = np.flatnonzero(take & (kind == _EQUALITY))
    k = len(doubled)
    kind = kind.copy()
    kind[take] = _ONE_SIDED
    if efc.is_sparse:
        nnz = efc.rownnz[:nefc]
        adr = efc.rowadr[:nefc]
        j, colind = efc.j, efc.colind
        tail = np.concatenate([np.arange(adr[r], adr[r] + nnz[r]) for r in doubled]) if k else np.zeros(0, int)
        end = len(j)
        rownnz = np.concatenate([nnz, nnz[doubled]])
        rowadr = np.concatenate([adr, (end + np.cumsum(nnz[doubled]) - nnz[doubled]).astype(adr.dtype)])
        j = np.concatenate([j, -j[tail]])
        colind = np.concatenate([colind, colind[tail]])
    else:
        dense = efc.j[:nefc * nv].reshape(nefc, nv)
        j = np.concatenate([dense, -dense[doubled]]).ravel()
        rownnz, rowadr, colind = efc.rownnz, efc.rowadr, efc.colind
    grown = lambda a, sign=1.0: np.concatenate([a[:nefc], sign * a[:nefc][doubled]])  # noqa: E731
    solvable = Efc(efc.is_sparse, nefc + k, nv, np.ascontiguousarray(j), rownnz.astype(efc.rownnz.dtype),
                   rowadr.astype(efc.rowadr.dtype), colind.astype(efc.colind.dtype),
                   np.concatenate([kind, np.full(k, _ONE_SIDED, dtype=kind.dtype)]),
                   np.concatenate([efc.force[:nefc], np.zeros(k)]), grown(efc.aref, -1.0), grown(efc.r),
                   grown(efc.diag_a))
    return SolvableRows(solvable, doubled)
