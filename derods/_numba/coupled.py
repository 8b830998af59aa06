"""Compiled mirror of :mod:`derods.sim.coupled`: the coupled step's elementwise work
between its matrix products, and where the held vertices go.

The products (K_fq^T y, y v_q, ...) stay numpy's: the same BLAS calls on the same
layouts, hence the same rounding, step for step. What lies between them (scalings,
differences, gathers by the holder dofs, copies) is a dozen numpy calls of ~0.5 us each
on arrays of a few dofs; here each stretch is one call.
"""

from __future__ import annotations

import numba as nb

from .dense import lu_factor


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
