"""Compiled mirror of :mod:`derods.sim.coupled`: MuJoCo's rows split for the bordered
contact solve, the coupled step's elementwise work between its matrix products, the
rows' forces out, and where the held vertices go.

The products (K_fq^T y, y v_q, ...) stay numpy's: the same BLAS calls on the same
layouts, hence the same rounding, step for step. What lies between them (scalings,
differences, gathers by the holder dofs, copies) is a dozen numpy calls of ~0.5 us each
on arrays of a few dofs; here each stretch is one call.

Every array these kernels return is allocated in them (C-ordered, of the dtypes their code
fixes), so a bundle of them has one numba type whatever the step: the coupled step keys
its calls on them by what they are made from (:meth:`derods._numba.calls.Bound.keyed`).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .cone_rows import block_cones, cone_groups, share_patterns
from .cones import Cones
from .contact_rows import Rows, transpose_apply_all
from .row_split import efc_triplets, split_bordered_rows
from .dense import lu_factor


class BorderedRows(NamedTuple):
    """MuJoCo's rows of a step split for a contact solve over n local dofs bordered by m
    (:func:`bordered_rows`): efc (k,) the k rows derods solves (MuJoCo's numbers, banded
    first); rows (:class:`derods._numba.contact_rows.Rows`) their entries on the local
    dofs, jq (k, m) on the border's; ext (n,) and ext_q (m,) [N] MuJoCo's force of the rows
    it keeps on either; aref (k,) [m/s^2] the rows' reference accelerations and ratio (k,)
    MuJoCo's R / diagA (its impedance, :func:`derods._numba.row_weights.row_weights`); cones
    (:class:`derods._numba.cones.Cones`) the elliptic contacts among them."""

    efc: np.ndarray
    rows: Rows
    jq: np.ndarray
    ext: np.ndarray
    ext_q: np.ndarray
    aref: np.ndarray
    ratio: np.ndarray
    cones: Cones


@nb.njit(cache=True)
def bordered_rows(efc, cone_contacts, supported_types, own, local_of_dof, border_of_dof, n, m, width):
    """MuJoCo's rows (``efc``, :class:`derods._numba.contact.Efc`) split for a solve over n
    local dofs bordered by m more (:func:`derods._numba.row_split.split_bordered_rows`;
    local_of_dof, border_of_dof (nv,): each MuJoCo dof's place among them, -1 elsewhere),
    in one call: the supported types (supported_types), the rows ``own`` (nefc,) bool
    or empty that take no force at all (neither solved nor MuJoCo's: a held edge against
    its own holder), the far rows as CSR, an elliptic contact's rows as its cone
    (cone_contacts: :class:`derods._numba.cone_rows.ConeContacts`)
    and the solved rows' aref and R / diagA. Returns a :class:`BorderedRows`."""
    nefc = efc.nefc
    row, col, val = efc_triplets(efc.is_sparse, nefc, efc.nv, efc.j, efc.rownnz, efc.rowadr, efc.colind)
    supported = np.zeros(nefc, dtype=np.bool_)
    force = np.empty(nefc)
    for r in range(nefc):
        for t in supported_types:
            if efc.type[r] == t:
                supported[r] = True
        force[r] = efc.force[r]
        if len(own) and own[r]:
            supported[r] = False
            force[r] = 0.0
    numbers = np.arange(nefc)
    group = cone_groups(numbers, efc.type, cone_contacts)
    solved, kb, col0, jw, far, jq, ext, ext_q = split_bordered_rows(row, col, val, local_of_dof, border_of_dof,
                                                                   group, supported, force, n, m, width)
    cones = block_cones(solved, numbers, efc.type, group, cone_contacts)
    fptr, fcol, fval = share_patterns(far[0], far[1], far[2], kb, cones) if len(cones.dim) else far
    aref = np.empty(len(solved))
    ratio = np.empty(len(solved))
    for i in range(len(solved)):
        aref[i] = efc.aref[solved[i]]
        ratio[i] = efc.r[solved[i]] / efc.diag_a[solved[i]]
    return BorderedRows(solved, Rows(col0, jw, fptr, fcol, fval), jq, ext, ext_q, aref, ratio, cones)


@nb.njit(cache=True)
def row_forces_into(rows, lam, force, efc_force):
    """The forces of the solved rows ``rows`` (:class:`BorderedRows`) at their multipliers
    lam (k,) [N]: force (n,) <- ext + J^T lam on the first n local dofs (the rods'),
    efc_force[efc] <- lam (MuJoCo's efc_force, which its readers look at)."""
    f = rows.ext + transpose_apply_all(rows.rows, lam, len(rows.ext))
    force[:] = f[:len(force)]
    for i in range(len(rows.efc)):
        efc_force[rows.efc[i]] = lam[i]


@nb.njit(cache=True)
def start_into(start, yv, coef, h_qq, kfy, s, held, y0, schur):
    """y0 (n,) <- start[:n] - coef yv [m/s^2] and schur (m, m) <- h_qq less s kfy on the
    rows and columns ``held`` (k,) (the held dofs' places among the m): the coupled
    step's unconstrained rod acceleration with the holders' velocity, coef yv = (b + h) / s
    A^-1 s K_fq v_q, and the Schur complement H_qq - s K_qf A^-1 s K_fq
    (:mod:`derods.sim.holders`)."""
    for j in range(len(y0)):
        y0[j] = start[j] - coef * yv[j]
    schur[:] = h_qq
    for i in range(len(held)):
        for j in range(len(held)):
            schur[held[i], held[j]] -= s * kfy[i, j]


@nb.njit(cache=True)
def force_into(qfrc_smooth, tree, ext_q, held, bh, kfv, kqv, s, ky0, schur, force, lu, piv):
    """force (m,) [N or N m] <- qfrc_smooth[tree] + ext_q, less bh (kfv + kqv) + s ky0 on
    the held dofs (held (k,): their places among the m): the right-hand side of the
    holders' Schur complement system (kfv = K_qf v_f, kqv = K_qq v_q, ky0 = K_qf y0,
    bh = b + h); lu, piv <- the factors of schur (m, m) (:func:`derods._numba.dense.lu_factor`)."""
    for i in range(len(tree)):
        force[i] = qfrc_smooth[tree[i]] + ext_q[i]
    for j in range(len(held)):
        force[held[j]] -= bh * (kfv[j] + kqv[j]) + s * ky0[j]
    lu[:] = schur
    lu_factor(lu, piv)


@nb.njit(cache=True)
def holder_steps_into(qvel, dofs, aq, in_tree, h, out):
    """out (k,) <- h (qvel[dofs] + h aq[in_tree]) [m or rad]: how far MuJoCo's integrator
    moves the holder dofs ``dofs`` (k,) this step with their trees' acceleration aq (m,)
    (in_tree (k,): each dof's place in aq)."""
    for j in range(len(dofs)):
        out[j] = h * (qvel[dofs[j]] + h * aq[in_tree[j]])


@nb.njit(cache=True)
def moved_into(x, vertex, dx, out):
    """out (n_vertices, 3) <- x, the vertices ``vertex`` (H,) moved by dx (3H,) [m]."""
    out[:] = x
    for c in range(len(vertex)):
        for a in range(3):
            out[vertex[c], a] = x[vertex[c], a] + dx[3 * c + a]
