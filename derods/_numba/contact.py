"""Compiled mirror of :mod:`derods.sim.contact`: MuJoCo's contact problem re-solved in
the metric of the implicit step, from MuJoCo's rows to the corrected acceleration.

Each function follows the numbered steps of :mod:`derods.sim.contact`'s docstring;
the arrays of the implicit system are those of
:class:`derods.sim.implicit.ImplicitSystem` (band, factor, twist terms).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import cholesky_into, solve_into
from .contact_rows import (apply_rows, efc_triplets, exact_line_search, rows_band, rows_diag,
                           split_rows, transpose_apply_rows)
from .implicit import k_matvec_into, sm_solve_into
from .banded import banded_inverse_band


@nb.njit(cache=True)
def _solve_columns(ab, g, tw_lo, tw_hi, tw_c, s, cols):
    """(B + E + sum_i s c_i g_i g_i^T)^-1 applied to each row of cols (m, n), in place:
    factor the band ab (A's band plus the rows' band E), solve, then one Sherman-Morrison
    update per twist term with z_i = (B + E)^-1 g_i over the whole length (the rows' band
    may couple rods), applied in turn."""
    n = ab.shape[1]
    lb = np.empty_like(ab)
    cholesky_into(ab, lb)
    for c in range(cols.shape[0]):
        solve_into(lb, cols[c], 0, n)
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        z = np.zeros(n)
        for j in range(lo, hi):
            z[j] = g[j]
        solve_into(lb, z, 0, n)
        gz = 0.0
        for j in range(lo, hi):
            gz += g[j] * z[j]
        sc = s * tw_c[i]
        for c in range(cols.shape[0]):
            gx = 0.0
            for j in range(lo, hi):
                gx += g[j] * cols[c, j]
            f = sc * gx / (1.0 + sc * gz)
            for j in range(n):
                cols[c, j] -= z[j] * f


@nb.njit(cache=True)
def newton_direction(a_band, g, tw_lo, tw_hi, tw_c, s, col0, jw, jf, w, grad):
    """H^-1 grad for H = A + J_b^T W_b J_b + J_f^T W_f J_f: a banded solve with the banded
    rows added to A's band, and the active far rows as a low-rank (Woodbury) update."""
    n = a_band.shape[1]
    kb = len(col0)
    extra = rows_band(col0, jw, w[:kb], n)
    ab = a_band.copy()
    for d in range(extra.shape[0]):
        for j in range(n):
            ab[d, j] += extra[d, j]
    n_act = 0
    for r in range(jf.shape[0]):
        if w[kb + r] > 0:
            n_act += 1
    cols = np.empty((1 + n_act, n))
    cols[0] = grad
    act = np.empty(n_act, dtype=np.int64)
    q = 0
    for r in range(jf.shape[0]):
        if w[kb + r] > 0:
            act[q] = r
            cols[1 + q] = jf[r]
            q += 1
    _solve_columns(ab, g, tw_lo, tw_hi, tw_c, s, cols)
    if n_act == 0:
        return cols[0].copy()
    y = cols[0]
    zt = cols[1:]  # (n_act, n): rows of Z^T
    small = np.zeros((n_act, n_act))
    rhs = np.zeros(n_act)
    for p in range(n_act):
        small[p, p] = 1.0 / w[kb + act[p]]
        jp = jf[act[p]]
        for q in range(n_act):
            acc = 0.0
            for j in range(n):
                acc += jp[j] * zt[q, j]
            small[p, q] += acc
        acc = 0.0
        for j in range(n):
            acc += jp[j] * y[j]
        rhs[p] = acc
    corr = np.linalg.solve(small, rhs)
    out = y.copy()
    for q in range(n_act):
        for j in range(n):
            out[j] -= zt[q, j] * corr[q]
    return out


@nb.njit(cache=True)
def newton(k_band, a_band, g, tw_lo, tw_hi, tw_c, s, mass, m_coef, a0, col0, jw, jf, aref, d, max_iter, tol):
    """Minimize 1/2 (a - a0)^T A (a - a0) + sum_i 1/2 d_i min(J_i a - aref_i, 0)^2 by
    Newton's method with an exact line search. Returns (a, lam, iterations)."""
    n = len(a0)
    a = a0.copy()
    am = np.zeros(n)  # A (a - a0), updated along the steps instead of recomputed
    jar = apply_rows(col0, jw, jf, a) - aref
    k = len(jar)
    scale = 1e-300
    m1 = 0.0
    for j in range(n):
        m1 = max(m1, abs(mass[j] * a0[j]))
    m2 = 0.0
    for i in range(k):
        m2 = max(m2, abs(d[i] * aref[i]))
    scale = m1 + m2 + 1e-300
    w = np.empty(k)
    kd = np.empty(n)
    it = 0
    for it in range(1, max_iter + 1):
        for i in range(k):
            w[i] = d[i] if jar[i] < 0 else 0.0
        grad = am + transpose_apply_rows(col0, jw, jf, w * jar, n)
        gmax = 0.0
        for j in range(n):
            gmax = max(gmax, abs(grad[j]))
        if gmax <= tol * scale:
            break
        delta = -newton_direction(a_band, g, tw_lo, tw_hi, tw_c, s, col0, jw, jf, w, grad)
        jd = apply_rows(col0, jw, jf, delta)
        k_matvec_into(k_band, g, tw_lo, tw_hi, tw_c, delta, kd)
        ad = s * kd + mass * m_coef * delta
        t = exact_line_search(jar, jd, d, float(delta @ ad), float(delta @ am))
        a = a + t * delta
        am = am + t * ad
        jar = jar + t * jd
        smax = 0.0
        amax = 0.0
        for j in range(n):
            smax = max(smax, abs(t * delta[j]))
            amax = max(amax, abs(a[j]))
        if smax <= tol * (amax + 1e-300):
            break
    jar = apply_rows(col0, jw, jf, a) - aref
    lam = np.where(jar < 0, -d * jar, 0.0)
    return a, lam, it


@nb.njit(cache=True)
def delassus_diagonal(lb, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, jf):
    """diag(J A^-1 J^T) of every row: banded rows from the band of B^-1 (Takahashi) with
    the twist terms' Sherman-Morrison corrections; far rows by one solve each."""
    n = lb.shape[1]
    zb = banded_inverse_band(lb)
    diag_b = rows_diag(col0, jw, zb)
    for i in range(len(tw_lo)):
        zi = np.zeros(n)
        lo, hi = tw_lo[i], tw_hi[i]
        for j in range(lo, hi):
            zi[j] = z[j]
        wi = s * tw_c[i] / den[i]
        jz = apply_rows(col0, jw, np.zeros((0, n)), zi)
        for r in range(len(col0)):
            diag_b[r] -= wi * jz[r] * jz[r]
    kb = len(col0)
    out = np.empty(kb + jf.shape[0])
    out[:kb] = diag_b
    for r in range(jf.shape[0]):
        col = jf[r].copy()
        sm_solve_into(lb, g, tw_lo, tw_hi, tw_c, s, z, den, col)
        acc = 0.0
        for j in range(n):
            acc += jf[r, j] * col[j]
        out[kb + r] = acc
    return out


@nb.njit(cache=True)
def contact_step(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind, efc_type, efc_force, efc_aref, efc_r,
                 efc_diag_a, supported_types, local_of_dof, width, k_band, a_band, lb, g, tw_lo, tw_hi, tw_c, s,
                 z, den, mass, m_coef, a0, a_out, force_out, max_iter, tol):
    """MuJoCo's constraint rows on the rod dofs, re-solved in the implicit metric.

    1. Split the rows (:func:`split_rows`): derods solves the rows that touch only rod
       dofs and are of a supported type; the others keep MuJoCo's force (ext).
    2. Rescale the rows' weights D = 1 / R to the implicit metric, keeping MuJoCo's
       impedance: R = (R / diagA)_MuJoCo * diag(J A^-1 J^T).
    3. From a0 + A^-1 ext, minimize MuJoCo's primal problem by Newton's method.
    Writes a_out (n,) [m/s^2] and force_out (n,) [N] (ext + J^T lam). Returns 0 if no
    row touches a rod dof (nothing written), 1 otherwise.
    """
    n = len(a0)
    row, col, val = efc_triplets(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind)
    supported = np.zeros(nefc, dtype=np.bool_)
    for r in range(nefc):
        for q in range(len(supported_types)):
            if efc_type[r] == supported_types[q]:
                supported[r] = True
    efc, kb, col0, jw, jf, ext = split_rows(row, col, val, local_of_dof, supported, efc_force[:nefc], n, width)
    any_ext = False
    for j in range(n):
        if ext[j] != 0.0:
            any_ext = True
            break
    if len(efc) == 0 and not any_ext:
        return 0
    a = a0.copy()
    if any_ext:
        e = ext.copy()
        sm_solve_into(lb, g, tw_lo, tw_hi, tw_c, s, z, den, e)
        a += e
    force_out[:] = ext
    if len(efc):
        aref = np.empty(len(efc))
        r_over_diag = np.empty(len(efc))
        for i in range(len(efc)):
            aref[i] = efc_aref[efc[i]]
            r_over_diag[i] = efc_r[efc[i]] / efc_diag_a[efc[i]]
        d = 1.0 / (r_over_diag * delassus_diagonal(lb, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, jf))
        a, lam, _ = newton(k_band, a_band, g, tw_lo, tw_hi, tw_c, s, mass, m_coef, a, col0, jw, jf, aref, d,
                           max_iter, tol)
        force_out += transpose_apply_rows(col0, jw, jf, lam, n)
    a_out[:] = a
    return 1
