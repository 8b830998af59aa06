"""Compiled mirror of :mod:`derods.sim.contact`: MuJoCo's contact problem re-solved in
the metric of the implicit step, from MuJoCo's rows to the corrected acceleration.

Each function follows the numbered steps of :mod:`derods.sim.contact`'s docstring;
the arrays of the implicit system are those of
:class:`derods.sim.implicit.ImplicitSystem` (band, factor, twist terms). Far rows
(rows that touch dofs too far apart for the band: self-contact, rod-rod contact)
are kept sparse, as CSR (``fptr``, ``fcol``, ``fval``).
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .banded import cholesky_into, inverse_band, solve_columns, solve_into
from .contact_rows import efc_triplets, exact_line_search, rows_apply, rows_band, rows_diag, rows_transpose_apply
from .contact_rows import split_rows
from .contact_blocks import partition
from .implicit import k_matvec_into, sm_solve_into

#: m dofs that border the band of a contact solve (bodies holding rods, solved with them):
#: h_fq (n, m) and h_qq (m, m) the coupled step matrix's border and corner, j_q (k, m) the
#: rows' entries on them, a0 (m,) their unconstrained acceleration.
Border = namedtuple("Border", ["h_fq", "h_qq", "j_q", "a0"])


@nb.njit(cache=True)
def no_border(n, k):
    """The empty border (m = 0) of a solve over n dofs and k rows."""
    return Border(np.zeros((n, 0)), np.zeros((0, 0)), np.zeros((k, 0)), np.zeros(0))


@nb.njit(cache=True)
def far_rows_csr(jf):
    """Far rows (k_f, n), dense, as CSR: (fptr (k_f + 1,), fcol, fval)."""
    k, n = jf.shape
    fptr = np.zeros(k + 1, dtype=np.int64)
    for r in range(k):
        c = 0
        for j in range(n):
            if jf[r, j] != 0.0:
                c += 1
        fptr[r + 1] = fptr[r] + c
    fcol = np.empty(fptr[k], dtype=np.int64)
    fval = np.empty(fptr[k])
    q = 0
    for r in range(k):
        for j in range(n):
            if jf[r, j] != 0.0:
                fcol[q] = j
                fval[q] = jf[r, j]
                q += 1
    return fptr, fcol, fval


@nb.njit(cache=True)
def apply_all(col0, jw, fptr, fcol, fval, a):
    """J a over the banded rows (first) and the far rows, shape (k_b + k_f,)."""
    kb = len(col0)
    kf = len(fptr) - 1
    out = np.empty(kb + kf)
    out[:kb] = rows_apply(col0, jw, a)
    for r in range(kf):
        acc = 0.0
        for q in range(fptr[r], fptr[r + 1]):
            acc += fval[q] * a[fcol[q]]
        out[kb + r] = acc
    return out


@nb.njit(cache=True)
def transpose_apply_all(col0, jw, fptr, fcol, fval, lam, n):
    """J^T lam over the banded and the far rows, shape (n,)."""
    kb = len(col0)
    out = rows_transpose_apply(col0, jw, lam[:kb], n)
    for r in range(len(fptr) - 1):
        lr = lam[kb + r]
        if lr != 0.0:
            for q in range(fptr[r], fptr[r + 1]):
                out[fcol[q]] += fval[q] * lr
    return out


@nb.njit(cache=True)
def _far_columns(fptr, fcol, fval, n):
    """The far rows' transposes side by side, (n, k_f), and their first nonzero dof."""
    kf = len(fptr) - 1
    cols = np.zeros((n, kf))
    first = n
    for r in range(kf):
        for q in range(fptr[r], fptr[r + 1]):
            cols[fcol[q], r] = fval[q]
            first = min(first, fcol[q])
    return cols, first


@nb.njit(cache=True)
def _twist_update(g, tw_lo, tw_hi, tw_c, s, ztw, cols):
    """Sherman-Morrison for each twist term in turn, on every column of cols (n, m):
    x -= z_i (s c_i g_i.x) / (1 + s c_i g_i.z_i), z_i = ztw[:, i] (B^-1 g_i)."""
    n = cols.shape[0]
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        gz = 0.0
        for j in range(lo, hi):
            gz += g[j] * ztw[j, i]
        sc = s * tw_c[i]
        for c in range(cols.shape[1]):
            gx = 0.0
            for j in range(lo, hi):
                gx += g[j] * cols[j, c]
            f = sc * gx / (1.0 + sc * gz)
            for j in range(n):
                cols[j, c] -= ztw[j, i] * f


@nb.njit(cache=True)
def newton(k_band, a_band, g, tw_lo, tw_hi, tw_c, s, mass, m_coef, a0, col0, jw, fptr, fcol, fval, aref, d,
           border, max_iter, tol):
    """Minimize 1/2 (a - a0)^T H (a - a0) + sum_i 1/2 d_i min(J_i a - aref_i, 0)^2 by
    Newton's method with an exact line search. Returns (a, a_q, lam, iterations).

    H is A (band, twist terms) over the n local dofs, bordered by m dofs q
    (:class:`Border`: H_fq, H_qq, the rows' q entries and a_q's start; m = 0 for none):
    every row is J_i = [J_f,i, J_q,i]. Each Newton step solves with B = A's band plus the
    active banded rows, factored (and the far rows solved against it) only when the
    banded rows' active set changes; the active far rows enter as a Woodbury update of a
    small dense system, and the border by its Schur complement on B (m more solves)."""
    n = len(a0)
    kb = len(col0)
    kf = len(fptr) - 1
    k = kb + kf
    n_tw = len(tw_lo)
    hfq, hqq, jq = border.h_fq, border.h_qq, border.j_q
    m = hqq.shape[0]
    a = a0.copy()
    aq = border.a0.copy()
    am = np.zeros(n)  # H (a - a0), updated along the steps instead of recomputed
    amq = np.zeros(m)
    jar = apply_all(col0, jw, fptr, fcol, fval, a)
    if m:
        _add_border_apply(jq, aq, jar)
    for i in range(k):
        jar[i] -= aref[i]
    m1 = 0.0
    for j in range(n):
        m1 = max(m1, abs(mass[j] * a0[j]))
    for j in range(m):
        m1 = max(m1, abs(hqq[j, j] * aq[j]))
    m2 = 0.0
    for i in range(k):
        m2 = max(m2, abs(d[i] * aref[i]))
    scale = m1 + m2 + 1e-300
    w = np.empty(k)
    wjar = np.empty(k)
    w_factored = np.full(kb, -1.0)  # the banded weights B was last factored with
    ab = np.empty_like(a_band)
    lt = np.empty((n, a_band.shape[0]))
    ztw = np.zeros((n, n_tw))
    zf = np.zeros((n, kf))
    zf_ready = False
    far_cols, far_first = _far_columns(fptr, fcol, fval, n)
    kd = np.empty(n)
    ad = np.empty(n)
    adq = np.empty(m)
    delta = np.empty(n)
    dq = np.zeros(m)
    y = np.empty((n, 1))
    small = np.zeros((0, 0))
    act = np.zeros(0, dtype=np.int64)
    it = 0
    for it in range(1, max_iter + 1):
        for i in range(k):
            w[i] = d[i] if jar[i] < 0 else 0.0
            wjar[i] = w[i] * jar[i]
        grad = transpose_apply_all(col0, jw, fptr, fcol, fval, wjar, n)
        gmax = 0.0
        for j in range(n):
            grad[j] += am[j]
            gmax = max(gmax, abs(grad[j]))
        gq = np.zeros(m)
        for j in range(m):
            acc = amq[j]
            for i in range(k):
                acc += jq[i, j] * wjar[i]
            gq[j] = acc
            gmax = max(gmax, abs(acc))
        if gmax <= tol * scale:
            break
        same = it > 1  # B is factored in the first iteration, then when its rows change
        for i in range(kb):
            if w[i] != w_factored[i]:
                same = False
                break
        if not same:
            extra = rows_band(col0, jw, w[:kb], n)
            ab[:] = a_band
            for dd in range(extra.shape[0]):
                for j in range(n):
                    ab[dd, j] += extra[dd, j]
            cholesky_into(ab, lt)
            ztw[:] = 0.0
            for i in range(n_tw):
                for j in range(tw_lo[i], tw_hi[i]):
                    ztw[j, i] = g[j]
            if n_tw:
                solve_columns(lt, ztw, 0, n, 0)
            w_factored[:] = w[:kb]
            zf_ready = False
        # The Newton direction: -(B + twist)^-1 grad, then the far rows by Woodbury.
        for j in range(n):
            y[j, 0] = grad[j]
        solve_into(lt, y[:, 0], 0, n)
        _twist_update(g, tw_lo, tw_hi, tw_c, s, ztw, y)
        n_act = 0
        for r in range(kf):
            if w[kb + r] > 0:
                n_act += 1
        for j in range(n):
            delta[j] = -y[j, 0]
        if n_act:
            if not zf_ready:
                zf[:] = far_cols
                solve_columns(lt, zf, 0, n, far_first)
                _twist_update(g, tw_lo, tw_hi, tw_c, s, ztw, zf)
                zf_ready = True
            act = np.empty(n_act, dtype=np.int64)
            q = 0
            for r in range(kf):
                if w[kb + r] > 0:
                    act[q] = r
                    q += 1
            small = np.zeros((n_act, n_act))
            corr = np.zeros(n_act)
            for p in range(n_act):
                r = act[p]
                small[p, p] = 1.0 / w[kb + r]
                for qq in range(fptr[r], fptr[r + 1]):
                    col, val = fcol[qq], fval[qq]
                    corr[p] += val * y[col, 0]
                    for c in range(n_act):
                        small[p, c] += val * zf[col, act[c]]
            _spd_factor(small)
            _spd_solve_factored(small, corr)
            for c in range(n_act):
                zc = act[c]
                for j in range(n):
                    delta[j] += zf[j, zc] * corr[c]
        if m:
            # The border by its Schur complement: C = H_fq + J_f^T W J_q, E = H_qq + J_q^T W J_q,
            # Z = (B + far)^-1 C, S = E - C^T Z; S dq = -g_q - C^T delta, delta -= Z dq.
            cw, ew = _border_blocks(col0, jw, fptr, fcol, fval, hfq, hqq, jq, w, n)
            zc_ = cw.copy()
            solve_columns(lt, zc_, 0, n, 0)
            _twist_update(g, tw_lo, tw_hi, tw_c, s, ztw, zc_)
            if n_act:
                _woodbury_columns(zf, act, small, fptr, fcol, fval, zc_)
            for p in range(m):
                acc = -gq[p]
                for j in range(n):
                    acc -= cw[j, p] * delta[j]
                dq[p] = acc
                for c in range(m):
                    acc2 = 0.0
                    for j in range(n):
                        acc2 += cw[j, p] * zc_[j, c]
                    ew[p, c] -= acc2
            _spd_factor(ew)
            _spd_solve_factored(ew, dq)
            for j in range(n):
                acc = 0.0
                for c in range(m):
                    acc += zc_[j, c] * dq[c]
                delta[j] -= acc
        jd = apply_all(col0, jw, fptr, fcol, fval, delta)
        k_matvec_into(k_band, g, tw_lo, tw_hi, tw_c, delta, kd)
        d_a, d_g = 0.0, 0.0
        for j in range(n):
            ad[j] = s * kd[j] + mass[j] * m_coef * delta[j]
        if m:
            _add_border_apply(jq, dq, jd)
            for j in range(n):
                for c in range(m):
                    ad[j] += hfq[j, c] * dq[c]
            for p in range(m):
                acc = 0.0
                for c in range(m):
                    acc += hqq[p, c] * dq[c]
                for j in range(n):
                    acc += hfq[j, p] * delta[j]
                adq[p] = acc
                d_a += dq[p] * acc
                d_g += dq[p] * amq[p]
        for j in range(n):
            d_a += delta[j] * ad[j]
            d_g += delta[j] * am[j]
        t = exact_line_search(jar, jd, d, d_a, d_g)
        smax = 0.0
        amax = 0.0
        for j in range(n):
            a[j] += t * delta[j]
            am[j] += t * ad[j]
            smax = max(smax, abs(t * delta[j]))
            amax = max(amax, abs(a[j]))
        for j in range(m):
            aq[j] += t * dq[j]
            amq[j] += t * adq[j]
            smax = max(smax, abs(t * dq[j]))
            amax = max(amax, abs(aq[j]))
        for i in range(k):
            jar[i] += t * jd[i]
        if smax <= tol * (amax + 1e-300):
            break
    jar = apply_all(col0, jw, fptr, fcol, fval, a)
    if m:
        _add_border_apply(jq, aq, jar)
    lam = np.zeros(k)
    for i in range(k):
        r = jar[i] - aref[i]
        if r < 0:
            lam[i] = -d[i] * r
    return a, aq, lam, it


@nb.njit(cache=True)
def _add_border_apply(jq, aq, out):
    """out += J_q a_q: the rows' border entries jq (k, m) times a_q (m,)."""
    for i in range(jq.shape[0]):
        acc = 0.0
        for c in range(jq.shape[1]):
            acc += jq[i, c] * aq[c]
        out[i] += acc


@nb.njit(cache=True)
def _border_blocks(col0, jw, fptr, fcol, fval, hfq, hqq, jq, w, n):
    """C = H_fq + J_f^T W J_q (n, m) and E = H_qq + J_q^T W J_q (m, m) for row weights w."""
    kb = len(col0)
    m = hqq.shape[0]
    cw = hfq.copy()
    ew = hqq.copy()
    width = jw.shape[1]
    for i in range(len(w)):
        wi = w[i]
        if wi == 0.0:
            continue
        for c in range(m):
            wq = wi * jq[i, c]
            if wq == 0.0:
                continue
            for c2 in range(m):
                ew[c2, c] += jq[i, c2] * wq
            if i < kb:
                c0 = col0[i]
                for p in range(min(width, n - c0)):
                    cw[c0 + p, c] += jw[i, p] * wq
            else:
                r = i - kb
                for qq in range(fptr[r], fptr[r + 1]):
                    cw[fcol[qq], c] += fval[qq] * wq
    return cw, ew


@nb.njit(cache=True)
def _woodbury_columns(zf, act, small_factor, fptr, fcol, fval, cols):
    """cols <- cols - Z_f S^-1 U^T cols for the active far rows act (Woodbury's correction,
    with S = W^-1 + U^T Z_f already factored by :func:`_spd_factor`)."""
    n_act = len(act)
    for c in range(cols.shape[1]):
        corr = np.zeros(n_act)
        for p in range(n_act):
            r = act[p]
            for qq in range(fptr[r], fptr[r + 1]):
                corr[p] += fval[qq] * cols[fcol[qq], c]
        _spd_solve_factored(small_factor, corr)
        for p in range(n_act):
            zc = act[p]
            for j in range(cols.shape[0]):
                cols[j, c] -= zf[j, zc] * corr[p]


@nb.njit(cache=True)
def _spd_factor(a):
    """Cholesky factor of a small symmetric positive definite a, in place (lower part):
    the Woodbury system of the active far rows, the border's Schur complement."""
    m = a.shape[0]
    for j in range(m):
        acc = a[j, j]
        for q in range(j):
            acc -= a[j, q] * a[j, q]
        ljj = np.sqrt(acc)
        a[j, j] = ljj
        for i in range(j + 1, m):
            acc = a[i, j]
            for q in range(j):
                acc -= a[i, q] * a[j, q]
            a[i, j] = acc / ljj


@nb.njit(cache=True)
def _spd_solve_factored(a, b):
    """Solve L L^T x = b in place on b, L the factor :func:`_spd_factor` left in a."""
    m = a.shape[0]
    for i in range(m):
        acc = b[i]
        for q in range(i):
            acc -= a[i, q] * b[q]
        b[i] = acc / a[i, i]
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for q in range(i + 1, m):
            acc -= a[q, i] * b[q]
        b[i] = acc / a[i, i]


@nb.njit(cache=True)
def delassus_diagonal(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol, fval):
    """diag(J A^-1 J^T) of every row: banded rows from the band of B^-1 (Takahashi) with
    the twist terms' Sherman-Morrison corrections; far rows by solves, side by side."""
    n = lt.shape[0]
    zb = inverse_band(lt, jw.shape[1])
    diag_b = rows_diag(col0, jw, zb)
    for i in range(len(tw_lo)):
        zi = np.zeros(n)
        lo, hi = tw_lo[i], tw_hi[i]
        for j in range(lo, hi):
            zi[j] = z[j]
        wi = s * tw_c[i] / den[i]
        jz = rows_apply(col0, jw, zi)
        for r in range(len(col0)):
            diag_b[r] -= wi * jz[r] * jz[r]
    kb = len(col0)
    kf = len(fptr) - 1
    out = np.empty(kb + kf)
    out[:kb] = diag_b
    if kf:
        cols, first = _far_columns(fptr, fcol, fval, n)
        solve_columns(lt, cols, 0, n, first)
        for i in range(len(tw_lo)):  # A^-1 = B^-1 - w z z^T for each twist term
            lo, hi = tw_lo[i], tw_hi[i]
            wi = s * tw_c[i] / den[i]
            for r in range(kf):
                gx = 0.0
                for j in range(lo, hi):
                    gx += g[j] * cols[j, r]
                for j in range(lo, hi):
                    cols[j, r] -= z[j] * wi * gx
        for r in range(kf):
            acc = 0.0
            for q in range(fptr[r], fptr[r + 1]):
                acc += fval[q] * cols[fcol[q], r]
            out[kb + r] = acc
    return out


@nb.njit(cache=True)
def contact_step(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind, efc_type, efc_force, efc_aref, efc_r,
                 efc_diag_a, supported_types, local_of_dof, dof_off, width, k_band, a_band, lt, g, tw_lo, tw_hi,
                 tw_c, s, z, den, mass, m_coef, a0, a_out, force_out, max_iter, tol):
    """MuJoCo's constraint rows on the rod dofs, re-solved in the implicit metric.

    Rods are independent in A (its band is block diagonal by rod), so the rows are
    grouped into blocks of rods they bind together (one rod, or rods a rod-rod contact
    joins) and each block is solved on its own (:func:`solve_block`): a rod no row
    touches keeps a0 and costs nothing, and a block's Newton iterations and
    refactorizations stay its own. dof_off (n_rods + 1,): each rod's local dof range.
    Writes a_out (n,) [m/s^2] and force_out (n,) [N]. Returns 0 if no row touches a
    rod dof (nothing written), 1 otherwise.
    """
    row, col, val = efc_triplets(is_sparse, nefc, nv, efc_j, rownnz, rowadr, colind)
    n_blocks, idx, start, compact, rows, row_start, row_in_block, nz, nz_start, block_of_rod = partition(
        row, col, nefc, local_of_dof, dof_off)
    if n_blocks == 0:
        return 0
    supported = np.zeros(nefc, dtype=np.bool_)
    for r in range(nefc):
        for q in range(len(supported_types)):
            if efc_type[r] == supported_types[q]:
                supported[r] = True
    a_out[:] = a0
    force_out[:] = 0.0
    rod_of_tw = np.empty(len(tw_lo), dtype=np.int64)
    for i in range(len(tw_lo)):
        rod_of_tw[i] = np.searchsorted(dof_off, tw_lo[i], side="right") - 1
    for b in range(n_blocks):
        ids = idx[start[b]:start[b + 1]]
        m = len(ids)
        # The block's rows: row numbers within the block, columns in the block's dofs
        # (m: a dof of no rod, so that split_rows sees the row reach elsewhere).
        block_rows = rows[row_start[b]:row_start[b + 1]]
        ps = nz[nz_start[b]:nz_start[b + 1]]
        row_b = np.empty(len(ps), dtype=np.int64)
        col_b = np.empty(len(ps), dtype=np.int64)
        val_b = np.empty(len(ps))
        for q in range(len(ps)):
            p = ps[q]
            row_b[q] = row_in_block[row[p]]
            loc = local_of_dof[col[p]]
            col_b[q] = compact[loc] if loc >= 0 else m
            val_b[q] = val[p]
        local_b = np.arange(m + 1)
        local_b[m] = -1
        tw = np.flatnonzero(block_of_rod[rod_of_tw] == b)
        tw_lo_b = np.empty(len(tw), dtype=np.int64)
        tw_hi_b = np.empty(len(tw), dtype=np.int64)
        for q in range(len(tw)):
            tw_lo_b[q] = compact[tw_lo[tw[q]]]
            tw_hi_b[q] = compact[tw_hi[tw[q]] - 1] + 1
        a_b = np.empty(m)
        f_b = np.empty(m)
        solve_block(row_b, col_b, val_b, block_rows, supported[block_rows], efc_force[block_rows],
                    efc_aref[block_rows], efc_r[block_rows], efc_diag_a[block_rows], local_b, width,
                    np.ascontiguousarray(k_band[:, ids]), np.ascontiguousarray(a_band[:, ids]), lt[ids],
                    g[ids], tw_lo_b, tw_hi_b, tw_c[tw], s, z[ids], den[tw], mass[ids], m_coef, a0[ids], a_b, f_b,
                    max_iter, tol)
        for q in range(m):
            a_out[ids[q]] = a_b[q]
            force_out[ids[q]] = f_b[q]
    return 1


@nb.njit(cache=True)
def solve_block(row, col, val, efc_rows, supported, efc_force, efc_aref, efc_r, efc_diag_a, local_of_dof, width,
                k_band, a_band, lt, g, tw_lo, tw_hi, tw_c, s, z, den, mass, m_coef, a0, a_out, force_out, max_iter,
                tol):
    """One block of rods' rows (k of them, with the nonzeros row, col, val; efc_rows (k,):
    MuJoCo's numbers of the rows, for reference only) re-solved in the implicit metric.

    1. Split the rows (:func:`split_rows`): derods solves the rows that touch only rod
       dofs and are of a supported type; the others keep MuJoCo's force (ext).
    2. Rescale the rows' weights D = 1 / R to the implicit metric, keeping MuJoCo's
       impedance: R = (R / diagA)_MuJoCo * diag(J A^-1 J^T).
    3. From a0 + A^-1 ext, minimize MuJoCo's primal problem by Newton's method.
    Writes a_out (m,) [m/s^2] and force_out (m,) [N] (ext + J^T lam) on the block's dofs.
    """
    n = len(a0)
    efc, kb, col0, jw, jf, ext = split_rows(row, col, val, local_of_dof, supported, efc_force, n, width)
    a = a0.copy()
    any_ext = False
    for j in range(n):
        if ext[j] != 0.0:
            any_ext = True
            break
    if any_ext:
        e = ext.copy()
        sm_solve_into(lt, g, tw_lo, tw_hi, tw_c, s, z, den, e)
        a += e
    force_out[:] = ext
    if len(efc):
        fptr, fcol, fval = far_rows_csr(jf)
        aref = np.empty(len(efc))
        r_over_diag = np.empty(len(efc))
        for i in range(len(efc)):
            aref[i] = efc_aref[efc[i]]
            r_over_diag[i] = efc_r[efc[i]] / efc_diag_a[efc[i]]
        d = 1.0 / (r_over_diag * delassus_diagonal(lt, g, tw_lo, tw_hi, tw_c, s, z, den, col0, jw, fptr, fcol,
                                                   fval))
        a, _, lam, _ = newton(k_band, a_band, g, tw_lo, tw_hi, tw_c, s, mass, m_coef, a, col0, jw, fptr, fcol,
                              fval, aref, d, no_border(n, len(efc)), max_iter, tol)
        force_out += transpose_apply_all(col0, jw, fptr, fcol, fval, lam, n)
    a_out[:] = a
