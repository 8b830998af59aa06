"""Contact between rods and the scene, solved in the metric of the implicit step.

MuJoCo finds the contacts and sets up its soft-constraint rows for them (the
Jacobian ``efc_J``, reference accelerations ``efc_aref``, weights ``efc_D``).
Its own solver would find the contact forces with the bare vertex masses M,
as if each vertex were free; but within an implicit step a vertex is bound to
its neighbours by the stiffness h^2 K, and a contact force computed for the
wrong inertia is either far too weak (the rod sinks in) or, lagged to the
next step, pumps energy (chatter). So derods solves the same problem MuJoCo
solves, in the right metric A = M (1 + h a_m) + (h^2 + h b) K:

    minimize_a  1/2 (a - a0)^T A (a - a0) + sum_i 1/2 D_i min(J_i a - aref_i, 0)^2,

MuJoCo's primal formulation for pyramidal (and frictionless) contacts, with
a0 the unconstrained implicit acceleration. Each row of a rod touching a
static obstacle touches at most two neighbouring vertices, so the Hessian
A + J^T D J stays banded and Newton's method costs one banded Cholesky per
iteration. Rows that touch distant parts of a rod (self-contact, as in a knot)
or two rods enter the Newton step as a low-rank update. Rows that couple a rod
to other moving bodies, and elliptic-cone rows, keep the force MuJoCo's own
solver computed for them in the same step.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from .._numba.contact_rows import (exact_line_search, rows_apply, rows_band, rows_diag, rows_transpose_apply,
                       sparse_triplets, split_rows)
from .implicit import ImplicitSystem
from ..stencil import XX_BANDWIDTH

_W = XX_BANDWIDTH + 1  # width of a row's dof window that keeps the Hessian banded
_SUPPORTED = (int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
              int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS))


@dataclass
class Rows:
    """Constraint rows solved by derods.

    Most rows touch one or two neighbouring vertices and fit a window of 9 dofs
    ("banded" rows: ``col0``, ``jw``); a self-contact between distant parts of a
    rod does not ("far" rows: ``jf``), and enters the Newton step as a low-rank
    update. Per row, banded rows first, then far rows:

    aref: reference acceleration [m/s^2], shape (k,). d: row weight 1/R, shape (k,).
    efc: the rows' indices in MuJoCo's efc arrays, shape (k,).
    r_over_diag: MuJoCo's R / diagA, shape (k,) (see :meth:`rescale`).
    col0: first local dof of each banded row's window, shape (k_b,), int64.
    jw: banded rows' Jacobian entries in their windows, shape (k_b, 9).
    jf: far rows' Jacobians over all local dofs, shape (k_f, n).
    """

    col0: np.ndarray
    jw: np.ndarray
    aref: np.ndarray
    d: np.ndarray
    efc: np.ndarray
    r_over_diag: np.ndarray | None = None
    jf: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.efc)

    @property
    def n_banded(self) -> int:
        return len(self.col0)

    def apply(self, a: np.ndarray) -> np.ndarray:
        """J a for every row, shape (k,)."""
        out = rows_apply(self.col0, self.jw, np.ascontiguousarray(a, dtype=float))
        if self.jf is not None:
            out = np.concatenate([out, self.jf @ a])
        return out

    def transpose_apply(self, lam: np.ndarray, n: int) -> np.ndarray:
        """J^T lam, shape (n,)."""
        kb = self.n_banded
        out = rows_transpose_apply(self.col0, self.jw, np.ascontiguousarray(lam[:kb], dtype=float), n)
        if self.jf is not None:
            out = out + self.jf.T @ lam[kb:]
        return out

    def band(self, weights: np.ndarray, n: int) -> np.ndarray:
        """Lower band (9, n) of J_b^T diag(weights) J_b over the banded rows."""
        return rows_band(self.col0, self.jw, np.ascontiguousarray(weights[: self.n_banded]), n)

    def rescale(self, system: ImplicitSystem) -> None:
        """Recompute the row weights D = 1 / R for the implicit metric.

        MuJoCo sets R = (1 - d) / d * diagA with diagA its estimate of the
        Delassus diagonal J M^-1 J^T, which sees the bare vertex masses; in the
        implicit step a vertex is far heavier, so the same R would make every
        contact and friction row much softer than authored (friction creeps).
        Keeping the authored impedance d means R = (1 - d) / d * J A^-1 J^T,
        whose diagonal needs, for banded rows, only the entries of A^-1 inside
        the band, and for far rows one solve each.
        """
        zb, corrections = system.inverse_diagonal_terms()
        diag_a = rows_diag(self.col0, self.jw, zb)
        for zvec, w in corrections:
            diag_a -= w * rows_apply(self.col0, self.jw, zvec) ** 2
        if self.jf is not None:
            diag_a = np.concatenate([diag_a, np.einsum("kn,nk->k", self.jf, system.solve(self.jf.T))])
        self.d = 1.0 / (self.r_over_diag * diag_a)


def rod_rows(model: mujoco.MjModel, data: mujoco.MjData, local_of_dof: np.ndarray,
             n: int) -> tuple[Rows | None, np.ndarray]:
    """Split the constraint rows that act on rod dofs into derods' rows and external force.

    local_of_dof: local index of every MuJoCo dof in the rods' free dofs, -1 elsewhere, (nv,).
    n: number of local dofs. Returns (rows or None, external force [N] on the local dofs (n,)).
    """
    nefc = data.nefc
    if nefc == 0:
        return None, np.zeros(n)
    if mujoco.mj_isSparse(model):
        row, col, val = sparse_triplets(data.efc_J_rownnz[:nefc], data.efc_J_rowadr[:nefc],
                                        data.efc_J_colind, data.efc_J)
    else:
        dense = data.efc_J[: nefc * model.nv].reshape(nefc, model.nv)
        row, col = np.nonzero(dense)
        val = dense[row, col]
    types = data.efc_type[:nefc]
    supported = (types == _SUPPORTED[0]) | (types == _SUPPORTED[1])
    efc, kb, col0, jw, jf, ext = split_rows(row, col, val, local_of_dof, supported, data.efc_force[:nefc], n, _W)
    if not len(efc):
        return None, ext
    rows = Rows(col0, jw, data.efc_aref[efc].copy(), data.efc_D[efc].copy(), efc,
                data.efc_R[efc] / data.efc_diagA[efc], jf if len(efc) > kb else None)
    return rows, ext


def _newton_step(system: ImplicitSystem, rows: Rows, w: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """H^-1 grad for H = A + J_b^T W_b J_b + J_f^T W_f J_f: a banded solve, with the far
    rows as a low-rank (Woodbury) update."""
    extra = rows.band(w, system.n)
    kb = rows.n_banded
    if rows.jf is None or not np.any(w[kb:] > 0):
        return system.solve(grad, extra_band=extra)
    act = np.flatnonzero(w[kb:] > 0)
    jf, wf = rows.jf[act], w[kb:][act]
    sol = system.solve(np.column_stack([grad, jf.T]), extra_band=extra)
    y, z = sol[:, 0], sol[:, 1:]
    small = np.diag(1.0 / wf) + jf @ z
    return y - z @ np.linalg.solve(small, jf @ y)


def solve(system: ImplicitSystem, a0: np.ndarray, rows: Rows, max_iter: int = 30,
          tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray, int]:
    """Newton's method on the contact problem in the implicit metric.

    system: the step's :class:`derods.implicit.ImplicitSystem`.
    a0: unconstrained end-of-step acceleration [m/s^2], shape (n,).
    Returns (a [m/s^2] shape (n,), row forces lam [N] shape (k,), iterations).
    The objective is convex and piecewise quadratic; each Newton step is
    followed by an exact line search along its direction.
    """
    n = system.n
    a = a0.copy()
    am = np.zeros(n)  # A (a - a0), updated along the steps instead of recomputed
    jar = rows.apply(a) - rows.aref
    scale = np.max(np.abs(system.mass * a0)) + np.max(np.abs(rows.d * rows.aref)) + 1e-300
    it = 0
    for it in range(1, max_iter + 1):
        w = np.where(jar < 0, rows.d, 0.0)
        grad = am + rows.transpose_apply(w * jar, n)
        if np.max(np.abs(grad)) <= tol * scale:
            break
        delta = -_newton_step(system, rows, w, grad)
        # Exact line search on f(a + t delta): f'(t) is piecewise linear and increasing.
        jd = rows.apply(delta)
        ad = system.a_matvec(delta)
        t = exact_line_search(jar, jd, rows.d, float(delta @ ad), float(delta @ am))
        a = a + t * delta
        am = am + t * ad
        jar = jar + t * jd
        if np.max(np.abs(t * delta)) <= tol * (np.max(np.abs(a)) + 1e-300):
            break
    jar = rows.apply(a) - rows.aref
    lam = np.where(jar < 0, -rows.d * jar, 0.0)
    return a, lam, it
