"""Newton's direction among many far rows, compiled: conjugate gradients on H = A + J^T W J,
preconditioned with the band's factor (the far rows left out), for the contact solve of
:mod:`derods._numba.contact_newton` when Woodbury's dense system of the active far rows
would grow as their cube (a pile's thousands of rod-rod rows).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import solve_into
from .contact_rows import apply_all, transpose_apply_all
from .implicit import k_matvec_into, twist_update_columns

#: Conjugate gradients for Newton's direction among many far rows (:func:`cg_direction`):
#: the residual's norm relative to the gradient's, and an iteration cap. An inexact
#: direction costs Newton an iteration or two, not accuracy (it stops on the gradient, TOL
#: of :mod:`derods.sim.contact`): 25 cables of 41 vertices in a heap took 7-8 Newton
#: iterations and ~330 CG iterations a step at 1e-3, 6 and ~690 at 1e-10 (half the step),
#: preconditioned with B alone; with the far rows' own blocks in it
#: (:func:`far_blocks_into_band`), 8-12 Newton iterations of ~31 CG (~50 before); at 1e-2,
#: 8-14 of ~20 (the frame 51 -> 40 ms, the heap the same; 1e-1 no faster).
CG_TOL = 1e-2
CG_MAX_ITER = 500



@nb.njit(cache=True)
def h_apply(system, rows, w, v, kv, out):
    """out (n,) = H v, H = A + J^T W J (A: ``system``; J: ``rows``, weights w (k,));
    kv (n,): scratch."""
    mass, m_coef, s = system.mass, system.weights[0], system.weights[1]
    n = len(v)
    k_matvec_into(system, v, kv)
    jv = apply_all(rows, v)
    for i in range(len(jv)):
        jv[i] *= w[i]
    jt = transpose_apply_all(rows, jv, n)
    for j in range(n):
        out[j] = s * kv[j] + m_coef * mass[j] * v[j] + jt[j]


@nb.njit(cache=True)
def cg_direction(system, rows, w, lt, ztw, zspan, grad, delta):
    """Newton's direction delta (n,) = -H^-1 grad, H = A + J^T W J over every active row
    (weights w), by conjugate gradients from zero preconditioned with B + twist, H less
    the products between a far row's distant parts (factored: lt, ztw, zspan; see
    :func:`far_blocks_into_band` and :func:`derods._numba.contact_newton.newton`): each
    iterate lowers Newton's quadratic model, so any is a descent direction. Each far row's weight times its
    Delassus entry is MuJoCo's d / (1 - d) (the rows' weights keep its impedance), so the
    far rows lift H's spectrum over B's by tens, and CG_TOL is met in tens of iterations
    where Woodbury's dense system of the active far rows grows as their cube (a pile's
    thousands). Writes delta; returns the iterations."""
    n = len(grad)
    x = np.zeros(n)
    r = np.empty(n)
    hp = np.empty(n)
    kv = np.empty(n)
    zc = np.empty((n, 1))
    bnorm = 0.0
    for j in range(n):
        r[j] = -grad[j]
        bnorm += grad[j] * grad[j]
    bnorm = np.sqrt(bnorm)
    zc[:, 0] = r
    solve_into(lt, zc[:, 0], 0, n)
    twist_update_columns(system, ztw, zspan, zc)
    p = zc[:, 0].copy()
    rz = 0.0
    for j in range(n):
        rz += r[j] * zc[j, 0]
    it = 0
    for it in range(1, CG_MAX_ITER + 1):
        h_apply(system, rows, w, p, kv, hp)
        php = 0.0
        for j in range(n):
            php += p[j] * hp[j]
        if not php > 0.0:
            break
        alpha = rz / php
        rnorm = 0.0
        for j in range(n):
            x[j] += alpha * p[j]
            r[j] -= alpha * hp[j]
            rnorm += r[j] * r[j]
        if np.sqrt(rnorm) <= CG_TOL * bnorm:
            break
        zc[:, 0] = r
        solve_into(lt, zc[:, 0], 0, n)
        twist_update_columns(system, ztw, zspan, zc)
        rz_new = 0.0
        for j in range(n):
            rz_new += r[j] * zc[j, 0]
        beta = rz_new / rz
        rz = rz_new
        for j in range(n):
            p[j] = zc[j, 0] + beta * p[j]
    delta[:] = x
    return it


@nb.njit(cache=True)
def far_blocks_into_band(ab, fptr, fcol, fval, w):
    """Add to the lower band ab (W, n) each far row's blocks that fit it: the row's entries
    (CSR fptr, fcol, fval, columns ascending; weights w (k_f,)) cut into runs of columns
    spanning less than W (a rod-rod row's part on each rod, a self-contact's on each side),
    and w j_s j_s^T of each run s. What is left out, the products between runs, couples
    dofs far apart; the sum kept is positive semi-definite, so the band stays a
    preconditioner for conjugate gradients (:func:`cg_direction`) that sees each contact's
    stiffness on its own vertices."""
    band = ab.shape[0]
    for r in range(len(fptr) - 1):
        wr = w[r]
        if wr == 0.0:
            continue
        start = fptr[r]
        while start < fptr[r + 1]:
            end = start + 1
            while end < fptr[r + 1] and fcol[end] - fcol[start] < band:
                end += 1
            for a in range(start, end):
                va = wr * fval[a]
                ca = fcol[a]
                for b in range(a, end):
                    ab[fcol[b] - ca, ca] += fval[b] * va
            start = end

