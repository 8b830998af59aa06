"""Newton's direction among many far rows, compiled: conjugate gradients on H = A + J^T W J,
preconditioned with the band's factor (the far rows left out), for the contact solve of
:mod:`derods._numba.contact_newton` when Woodbury's dense system of the active far rows
would grow as their cube (a pile's thousands of rod-rod rows).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import solve_into
from .implicit import k_matvec_into, twist_update_columns

#: Conjugate gradients for Newton's direction among many far rows (:func:`cg_direction`):
#: the residual's norm relative to the gradient's (the forcing term, :func:`forcing`) and
#: an iteration cap. An inexact direction costs Newton an iteration or two, not accuracy
#: (it stops on the gradient, TOL of :mod:`derods.sim.contact`): 25 cables of 41 vertices
#: in a heap took 7-8 Newton iterations and ~330 CG iterations a step at 1e-3, 6 and ~690
#: at 1e-10 (half the step), preconditioned with B alone; with the far rows' own blocks in
#: it (:func:`far_blocks_into_band`), 8-12 Newton iterations of ~31 CG (~50 before); at
#: 1e-2, 8-14 of ~20 (the frame 51 -> 40 ms, the heap the same; 1e-1 throughout no faster).
#: The forcing term now moves between CG_TOL_MIN (the fixed 1e-2 of before) and
#: CG_TOL_MAX by Eisenstat and Walker's second choice, eta = CG_FORCING (|g_k| / |g_k-1|)^2
#: (SIAM J. Sci. Comput. 17, 1996): loose while Newton's gradient falls slowly (the first
#: iterations, while the active set changes), tight once it falls fast. 100 cables x 41,
#: steps 0.46-0.58 s of a drop: 253 CG iterations a step before, 217 with it (Newton 11.4
#: -> 12.1 iterations); with a floor of 1e-3, 224; with CG_FORCING 0.5, 249; with
#: CG_TOL_MAX 0.3, 240.
CG_TOL_MIN = 1e-2
CG_TOL_MAX = 1e-1
CG_FORCING = 0.9
CG_MAX_ITER = 500


@nb.njit(cache=True)
def forcing(eta, g, g_prev):
    """The relative tolerance of the next CG solve (see CG_TOL_MIN): eta the last one's, g
    and g_prev the largest entries of Newton's gradient now and at the last solve (g_prev
    <= 0: the first solve, CG_TOL_MAX). Eisenstat and Walker's safeguard keeps eta from
    falling much faster than the last one squared while that is still large."""
    if not g_prev > 0.0:
        return CG_TOL_MAX
    ratio = g / g_prev
    new = CG_FORCING * ratio * ratio
    if CG_FORCING * eta * eta > 0.1:
        new = max(new, CG_FORCING * eta * eta)
    return min(CG_TOL_MAX, max(CG_TOL_MIN, new))


@nb.njit(cache=True)
def h_apply(system, rows, w, v, kv, jt, out):
    """out (n,) = H v, H = A + J^T W J (A: ``system``; J: ``rows``, weights w (k,));
    kv, jt (n,): scratch."""
    mass, m_coef, s = system.mass, system.weights[0], system.weights[1]
    n = len(v)
    k_matvec_into(system, v, kv)
    gram_apply_into(rows, w, v, jt)
    for j in range(n):
        out[j] = s * kv[j] + m_coef * mass[j] * v[j] + jt[j]


@nb.njit(cache=True)
def gram_apply_into(rows, w, v, out):
    """out (n,) = J^T W J v over the banded rows, then the far rows
    (:class:`derods._numba.contact_rows.Rows`; weights w (k,)), each row's J_i v and its
    share in one pass over its entries; a row of weight 0 (inactive) costs nothing. The
    sums are those of :func:`derods._numba.contact_rows.apply_all` and
    :func:`derods._numba.contact_rows.transpose_apply_all`, in their order."""
    col0, jw, fptr, fcol, fval = rows
    n = len(v)
    kb = len(col0)
    width = jw.shape[1]
    out[:] = 0.0
    for i in range(kb):
        wi = w[i]
        if wi == 0.0:
            continue
        c0 = col0[i]
        m = min(width, n - c0)
        acc = 0.0
        for q in range(m):
            acc += jw[i, q] * v[c0 + q]
        lam = acc * wi
        for q in range(m):
            out[c0 + q] += jw[i, q] * lam
    for r in range(len(fptr) - 1):
        wr = w[kb + r]
        if wr == 0.0:
            continue
        acc = 0.0
        for q in range(fptr[r], fptr[r + 1]):
            acc += fval[q] * v[fcol[q]]
        lam = acc * wr
        if lam != 0.0:
            for q in range(fptr[r], fptr[r + 1]):
                out[fcol[q]] += fval[q] * lam


@nb.njit(cache=True)
def cg_direction(system, rows, w, lt, ztw, zspan, grad, delta, tol):
    """Newton's direction delta (n,) = -H^-1 grad, H = A + J^T W J over every active row
    (weights w), by conjugate gradients from zero preconditioned with B + twist, H less
    the products between a far row's distant parts (factored: lt, ztw, zspan; see
    :func:`far_blocks_into_band` and :func:`derods._numba.contact_newton.newton`): each
    iterate lowers Newton's quadratic model, so any is a descent direction. Each far row's weight times its
    Delassus entry is MuJoCo's d / (1 - d) (the rows' weights keep its impedance), so the
    far rows lift H's spectrum over B's by tens, and a tolerance tol (the residual's norm
    relative to the gradient's, :func:`forcing`) is met in tens of iterations where
    Woodbury's dense system of the active far rows grows as their cube (a pile's
    thousands). Writes delta; returns the iterations."""
    n = len(grad)
    x = np.zeros(n)
    r = np.empty(n)
    hp = np.empty(n)
    kv = np.empty(n)
    jt = np.empty(n)
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
        h_apply(system, rows, w, p, kv, jt, hp)
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
        if np.sqrt(rnorm) <= tol * bnorm:
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

