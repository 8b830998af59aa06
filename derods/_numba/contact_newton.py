"""The contact problem's Newton solve, compiled: minimize MuJoCo's primal objective in the
implicit step's metric, the band's rows by its Cholesky factor, far rows (self-contact,
rod-rod) by Woodbury's identity (past FAR_DENSE_MAX of them, by conjugate gradients:
:mod:`derods._numba.contact_cg`), and dofs that border the band (bodies holding rods,
:mod:`derods.sim.coupled`) by their Schur complement. The stage around it (rows from
MuJoCo, weights, blocks of rods) is :mod:`derods._numba.contact`; the rows' products are
:mod:`derods._numba.contact_rows`.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .banded import cholesky_into, solve_columns, solve_into
from .dense import spd_factor as _spd_factor, spd_solve_factored as _spd_solve_factored
from .contact_rows import FAR_DENSE_MAX, Rows, apply_all_into, exact_line_search, far_columns, rows_band_into
from .contact_rows import transpose_apply_all_into
from .cones import cone_forces, cone_line_search, virtual_jar, virtual_rows, write_virtual
from .contact_cg import CG_TOL_MAX, cg_direction, far_blocks_into_band, forcing
from .implicit import k_matvec_into, twist_spans, twist_update_columns

#: m dofs that border the band of a contact solve (bodies holding rods, solved with them):
#: h_fq (n, m) and h_qq (m, m) the coupled step matrix's border and corner, j_q (k, m) the
#: rows' entries on them, a0 (m,) their unconstrained acceleration.
Border = namedtuple("Border", ["h_fq", "h_qq", "j_q", "a0"])

@nb.njit(cache=True)
def no_border(n, k):
    """The empty border (m = 0) of a solve over n dofs and k rows."""
    return Border(np.zeros((n, 0)), np.zeros((0, 0)), np.zeros((k, 0)), np.zeros(0))


@nb.njit(cache=True)
def newton(system, a0, rows, aref, d, border, cones, max_iter, tol):
    """Minimize 1/2 (a - a0)^T H (a - a0) + sum_i 1/2 d_i min(J_i a - aref_i, 0)^2 by
    Newton's method with an exact line search. Returns (a, a_q, lam, iterations).

    H is A (``system``, a factored :class:`derods._numba.implicit.System`: band, twist terms)
    over the n local dofs, bordered by m dofs q
    (:class:`Border`: H_fq, H_qq, the rows' q entries and a_q's start; m = 0 for none):
    every row is J_i = [J_f,i, J_q,i]. Each Newton step solves with B = A's band plus the
    active banded rows, factored (and the far rows solved against it) only when the
    banded rows' active set changes; the active far rows enter as a Woodbury update of a
    small dense system, and the border by its Schur complement on B (m more solves).
    rows: the rows J (:class:`derods._numba.contact_rows.Rows`); aref (k,) their reference
    accelerations, d (k,) their weights; cones: the elliptic friction cones among them
    (:class:`derods._numba.cones.Cones`, their rows' cost MuJoCo's elliptic one instead;
    None for none: compiled then without a trace of them), which enter the linear algebra
    as virtual rows (:func:`derods._numba.cones.virtual_rows`)."""
    g, tw_lo, tw_hi, mass, a_band = system.g, system.tw_lo, system.tw_hi, system.mass, system.a_band
    s, m_coef = system.weights[1], system.weights[0]
    nc = 0 if cones is None else len(cones.dim)
    # The rows the Hessian and gradient see: the cones' virtual rows in place of theirs.
    vrows = rows if cones is None else Rows(rows.col0, rows.jw.copy(), rows.fptr, rows.fcol, rows.fval.copy())
    col0, jw, fptr, fcol, fval = vrows
    n = len(a0)
    kb = len(col0)
    kf = len(fptr) - 1
    k = kb + kf
    n_tw = len(tw_lo)
    hfq, hqq, jq = border.h_fq, border.h_qq, border.j_q
    jqv = jq if cones is None else jq.copy()  # the border entries of the rows the Hessian sees
    m = hqq.shape[0]
    if cones is not None:
        in_cone = np.zeros(k, dtype=np.bool_)
        for c in range(nc):
            for j in range(cones.dim[c]):
                in_cone[cones.rows[c, j]] = True
        basis = np.zeros((nc, 6, 6))
        wv = np.zeros((nc, 6))
    # The solve's vectors as the rows of three allocations (per dof, per border dof, per
    # row): an allocation costs as much as a window's products, and blocks of rods solve
    # their contacts every step.
    vn, vq, vk = np.empty((6, n)), np.empty((5, m)), np.empty((4, k))
    a, am, kd, ad, delta, grad = vn[0], vn[1], vn[2], vn[3], vn[4], vn[5]
    aq, amq, adq, dq, gq = vq[0], vq[1], vq[2], vq[3], vq[4]
    jar, w, wjar, jd = vk[0], vk[1], vk[2], vk[3]
    a[:] = a0
    aq[:] = border.a0
    am[:] = 0.0  # H (a - a0), updated along the steps instead of recomputed
    amq[:] = 0.0
    dq[:] = 0.0
    apply_all_into(rows, a, jar)
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
    ab = np.empty_like(a_band)
    lt = np.empty((n, a_band.shape[0]))
    ztw = np.zeros((n, n_tw))
    zspan = np.zeros((n_tw, 2), dtype=np.int64)
    # Many far rows and no border: Newton's direction by conjugate gradients (contact_cg),
    # preconditioned with B and the far rows' blocks that fit the band (their weights too
    # then decide when B is factored again).
    iterative = m == 0 and kf > FAR_DENSE_MAX
    w_factored = np.full(k if iterative else kb, -1.0)  # the weights B was last factored with
    zf = np.zeros((n, 0 if iterative else kf))
    zf_ready = False
    if iterative or kf == 0:
        far_cols, far_first = zf, n
    else:
        far_cols, far_first = far_columns(vrows, n)
    y = np.empty((n, 1))
    small = np.zeros((0, 0))
    act = np.zeros(0, dtype=np.int64)
    extra = np.empty((jw.shape[1], n))
    eta, g_cg = CG_TOL_MAX, 0.0  # the last CG solve's tolerance and gradient
    it = 0
    for it in range(1, max_iter + 1):
        for i in range(k):
            w[i] = d[i] if jar[i] < 0 else 0.0
            wjar[i] = w[i] * jar[i]
        cones_moved = False
        if cones is not None:
            cones_moved = virtual_rows(cones, jar, d, basis, wv)
            virtual_jar(cones, basis, wv, jar, w, wjar)
            if cones_moved:
                write_virtual(rows, vrows, jq, jqv, kb, cones, basis)
                if not iterative:
                    far_cols, far_first = far_columns(vrows, n)
        transpose_apply_all_into(vrows, wjar, grad)
        gmax = 0.0
        for j in range(n):
            grad[j] += am[j]
            gmax = max(gmax, abs(grad[j]))
        for j in range(m):
            acc = amq[j]
            for i in range(k):
                acc += jqv[i, j] * wjar[i]
            gq[j] = acc
            gmax = max(gmax, abs(acc))
        if gmax <= tol * scale:
            break
        same = it > 1 and not cones_moved  # B is factored first, then when its rows change
        for i in range(len(w_factored)):
            if w[i] != w_factored[i]:
                same = False
                break
        if not same:
            rows_band_into(col0, jw, w, extra)  # the banded rows' weights: w's first kb
            ab[:] = a_band
            for dd in range(extra.shape[0]):
                for j in range(n):
                    ab[dd, j] += extra[dd, j]
            if iterative:
                far_blocks_into_band(ab, fptr, fcol, fval, w[kb:])
            cholesky_into(ab, lt)
            ztw[:] = 0.0
            for i in range(n_tw):
                for j in range(tw_lo[i], tw_hi[i]):
                    ztw[j, i] = g[j]
            if n_tw:
                solve_columns(lt, ztw, 0, n, 0)
                twist_spans(ztw, zspan)
            w_factored[:] = w[:len(w_factored)]
            zf_ready = False
        # The Newton direction: -(B + twist)^-1 grad, then the far rows by Woodbury.
        for j in range(n):
            y[j, 0] = grad[j]
        solve_into(lt, y[:, 0], 0, n)
        twist_update_columns(system, ztw, zspan, y)
        n_act = 0
        for r in range(kf):
            if w[kb + r] > 0:
                n_act += 1
        for j in range(n):
            delta[j] = -y[j, 0]
        if n_act and iterative:
            eta = forcing(eta, gmax, g_cg)
            g_cg = gmax
            cg_direction(system, vrows, w, lt, ztw, zspan, grad, delta, eta)
        elif n_act:
            if not zf_ready:
                zf[:] = far_cols
                solve_columns(lt, zf, 0, n, far_first)
                twist_update_columns(system, ztw, zspan, zf)
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
            cw, ew = _border_blocks(vrows, hfq, hqq, jqv, w, n)
            zc_ = cw.copy()
            solve_columns(lt, zc_, 0, n, 0)
            twist_update_columns(system, ztw, zspan, zc_)
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
        apply_all_into(rows, delta, jd)
        k_matvec_into(system, delta, kd)
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
        if cones is None:
            t = exact_line_search(jar, jd, d, d_a, d_g)
        else:
            t = cone_line_search(jar, jd, d, in_cone, cones, d_a, d_g)
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
    apply_all_into(rows, a, jar)
    if m:
        _add_border_apply(jq, aq, jar)
    lam = np.zeros(k)
    for i in range(k):
        r = jar[i] - aref[i]
        if r < 0:
            lam[i] = -d[i] * r
        jar[i] = r
    if cones is not None:
        cone_forces(cones, jar, d, lam)
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
def _border_blocks(rows, hfq, hqq, jq, w, n):
    """C = H_fq + J_f^T W J_q (n, m) and E = H_qq + J_q^T W J_q (m, m) for row weights w
    (rows: :class:`derods._numba.contact_rows.Rows`)."""
    col0, jw, fptr, fcol, fval = rows
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
    with S = W^-1 + U^T Z_f already factored by :func:`derods._numba.dense.spd_factor`)."""
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
