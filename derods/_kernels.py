"""Compiled (numba) kernel for the per-step work of isotropic, naturally straight rods.

One call does, for every rod of a batch, what the numpy path of
:meth:`derods.rod.Rod.step_terms` does with several dozen array operations:
transport the reference frames in time, solve the quasistatic twist, and
evaluate the gradient and the positive semi-definite banded Hessian of
stretch + isotropic bending + the reduced twist. At a few hundred vertices a
numpy call costs more in overhead than in arithmetic; this kernel removes
that overhead. Open rods and rings share one loop: edge j joins vertices j
and j + 1 (mod n on a ring); joint k joins edges k, k + 1 of an open rod and
k - 1, k of a ring (:func:`derods.geometry.joint_pairs`). The band is written
with the vertices in a given order (identity for open rods,
:func:`derods.stencil.ring_order` for rings). tests/test_kernels.py checks it
against the numpy path, which in turn is checked against finite differences.

Formulas and conventions are those of :mod:`derods.energy`,
:mod:`derods.frames` and :mod:`derods.twist`; the lower banded layout is that
of :mod:`derods.stencil`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .geometry import CHI_MIN


@nb.njit(cache=True, inline="always")
def _add(ab, pos, vi, vj, r, c, v):
    """Add v to H[3 vi + r, 3 vj + c] of a symmetric matrix kept as its lower band, with
    vertex vi at place pos[vi] of the solve order. Of a diagonal block (vi == vj) only the
    lower triangle is added; an off-diagonal block lands in the lower half, transposed if
    its vertices come in the other order (each such block is added for one order only)."""
    row = 3 * pos[vi] + r
    col = 3 * pos[vj] + c
    if row < col:
        if vi == vj:
            return
        row, col = col, row
    if row - col >= ab.shape[0]:
        raise ValueError("a Hessian entry falls outside the band; check the vertex order")
    ab[row - col, col] += v


@nb.njit(cache=True)
def _step_one(x, u_prev, t_prev, rest_len, vlen, ks, alpha, beta, mbar, closed, pos, clamped, anchor_last,
              theta_first, theta_last, total_twist, u, t, theta, grad, ab, g_tw, ref, le, ja, jb, hab):
    nv = x.shape[0]
    ne = nv if closed else nv - 1
    nj = nv if closed else nv - 2
    energy = 0.0
    grad[:] = 0.0
    ab[:] = 0.0
    g_tw[:] = 0.0
    # Edges: tangents, time-parallel transport of the reference frames, stretching.
    for j in range(ne):
        jn = (j + 1) % nv
        e0 = x[jn, 0] - x[j, 0]
        e1 = x[jn, 1] - x[j, 1]
        e2 = x[jn, 2] - x[j, 2]
        lj = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        le[j] = lj
        c0, c1, c2 = e0 / lj, e1 / lj, e2 / lj
        t[j, 0], t[j, 1], t[j, 2] = c0, c1, c2
        p0, p1, p2 = t_prev[j, 0], t_prev[j, 1], t_prev[j, 2]
        k0, k1, k2 = p1 * c2 - p2 * c1, p2 * c0 - p0 * c2, p0 * c1 - p1 * c0
        s0, s1, s2 = p0 + c0, p1 + c1, p2 + c2
        opc = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
        cc = opc - 1.0
        w0, w1, w2 = u_prev[j, 0], u_prev[j, 1], u_prev[j, 2]
        kw = (k0 * w0 + k1 * w1 + k2 * w2) / opc
        v0 = cc * w0 + (k1 * w2 - k2 * w1) + k0 * kw
        v1 = cc * w1 + (k2 * w0 - k0 * w2) + k1 * kw
        v2 = cc * w2 + (k0 * w1 - k1 * w0) + k2 * kw
        vt = v0 * c0 + v1 * c1 + v2 * c2
        v0, v1, v2 = v0 - vt * c0, v1 - vt * c1, v2 - vt * c2
        nvv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        u[j, 0], u[j, 1], u[j, 2] = v0 / nvv, v1 / nvv, v2 / nvv
        strain = lj / rest_len[j] - 1.0
        energy += 0.5 * ks * rest_len[j] * strain * strain
        ten = ks * strain
        for a in range(3):
            grad[j, a] -= ten * t[j, a]
            grad[jn, a] += ten * t[j, a]
        kt = ks / rest_len[j]
        kg = max(ten, 0.0) / lj
        for r in range(3):
            for c in range(3):
                h = (kt - kg) * t[j, r] * t[j, c] + (kg if r == c else 0.0)
                _add(ab, pos, j, j, r, c, h)
                _add(ab, pos, jn, jn, r, c, h)
                _add(ab, pos, jn, j, r, c, -h)
    # Joints: isotropic bending and the reference twist with its gradient.
    for k in range(nj):
        # Edges ea, eb meet at vertex vm between vertices va and vn.
        if closed:
            ea, eb = (k - 1) % ne, k
            va, vm, vn = (k - 1) % nv, k, (k + 1) % nv
        else:
            ea, eb = k, k + 1
            va, vm, vn = k, k + 1, k + 2
        a0, a1, a2 = t[ea, 0], t[ea, 1], t[ea, 2]
        b0, b1, b2 = t[eb, 0], t[eb, 1], t[eb, 2]
        la, lb = le[ea], le[eb]
        s0, s1, s2 = a0 + b0, a1 + b1, a2 + b2
        chi = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
        kb0 = 2.0 * (a1 * b2 - a2 * b1) / chi
        kb1 = 2.0 * (a2 * b0 - a0 * b2) / chi
        kb2 = 2.0 * (a0 * b1 - a1 * b0) / chi
        # ja = (-2 [tb]x - kb s^T) / (la chi), jb = (2 [ta]x - kb s^T) / (lb chi)
        fa = 1.0 / (la * chi)
        fb = 1.0 / (lb * chi)
        kbv = (kb0, kb1, kb2)
        sv = (s0, s1, s2)
        for r in range(3):
            for c in range(3):
                ja[r, c] = -kbv[r] * sv[c] * fa
                jb[r, c] = -kbv[r] * sv[c] * fb
        ja[0, 1] += 2.0 * b2 * fa
        ja[0, 2] -= 2.0 * b1 * fa
        ja[1, 0] -= 2.0 * b2 * fa
        ja[1, 2] += 2.0 * b0 * fa
        ja[2, 0] += 2.0 * b1 * fa
        ja[2, 1] -= 2.0 * b0 * fa
        jb[0, 1] -= 2.0 * a2 * fb
        jb[0, 2] += 2.0 * a1 * fb
        jb[1, 0] += 2.0 * a2 * fb
        jb[1, 2] -= 2.0 * a0 * fb
        jb[2, 0] -= 2.0 * a1 * fb
        jb[2, 1] += 2.0 * a0 * fb
        cb = alpha / vlen[k]
        energy += cb * (kb0 * kb0 + kb1 * kb1 + kb2 * kb2)
        two_c = 2.0 * cb
        for c in range(3):
            ga = two_c * (ja[0, c] * kb0 + ja[1, c] * kb1 + ja[2, c] * kb2)
            gb = two_c * (jb[0, c] * kb0 + jb[1, c] * kb1 + jb[2, c] * kb2)
            grad[va, c] -= ga
            grad[vm, c] += ga - gb
            grad[vn, c] += gb
        # Gauss-Newton Hessian 2c J^T J over (a, b), mapped to the three vertices.
        for r in range(6):
            for c in range(6):
                acc = 0.0
                for i in range(3):
                    jr = ja[i, r] if r < 3 else jb[i, r - 3]
                    jc = ja[i, c] if c < 3 else jb[i, c - 3]
                    acc += jr * jc
                hab[r, c] = two_c * acc
        for r in range(3):
            for c in range(3):
                haa, hab_, hba, hbb = hab[r, c], hab[r, c + 3], hab[r + 3, c], hab[r + 3, c + 3]
                _add(ab, pos, va, va, r, c, haa)
                _add(ab, pos, vm, vm, r, c, haa - hab_ - hba + hbb)
                _add(ab, pos, vn, vn, r, c, hbb)
                _add(ab, pos, vm, va, r, c, hba - haa)
                _add(ab, pos, vn, vm, r, c, hba - hbb)
                _add(ab, pos, vn, va, r, c, -hba)
        # Reference twist: angle from the transport of u^k (ta -> tb) to u^{k+1} about tb.
        w0, w1, w2 = u[ea, 0], u[ea, 1], u[ea, 2]
        q0, q1, q2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        cc = chi - 1.0
        kw = (q0 * w0 + q1 * w1 + q2 * w2) / chi
        v0 = cc * w0 + (q1 * w2 - q2 * w1) + q0 * kw
        v1 = cc * w1 + (q2 * w0 - q0 * w2) + q1 * kw
        v2 = cc * w2 + (q0 * w1 - q1 * w0) + q2 * kw
        z0, z1, z2 = u[eb, 0], u[eb, 1], u[eb, 2]
        sin_ = (v1 * z2 - v2 * z1) * b0 + (v2 * z0 - v0 * z2) * b1 + (v0 * z1 - v1 * z0) * b2
        cos_ = v0 * z0 + v1 * z1 + v2 * z2
        ref[k] = math.atan2(sin_, cos_)
        ia, ib = 0.5 / la, 0.5 / lb
        for c in range(3):
            g_tw[va, c] -= kbv[c] * ia
            g_tw[vm, c] += kbv[c] * (ia - ib)
            g_tw[vn, c] += kbv[c] * ib
    # Quasistatic twist (closed form, see derods.twist.solve_isotropic): theta of edge eb
    # follows theta of edge ea by d_k + mbar_k - ref_k across joint k (not across a ring's seam).
    lam = 0.0
    coef = 0.0
    if clamped:
        excess = total_twist if closed else theta_last - theta_first
        compliance = 0.0
        for k in range(nj):
            excess += ref[k] - mbar[k]
            compliance += vlen[k] / beta
        lam = 2.0 * excess / compliance
        coef = 2.0 / compliance
        energy += 0.25 * lam * lam * compliance
        theta[0] = 0.0 if closed else theta_first
        for k in range(1 if closed else 0, nj):
            eb = k if closed else k + 1
            theta[eb] = theta[eb - 1] + 0.5 * lam * vlen[k] / beta + mbar[k] - ref[k]
        for i in range(nv):
            for a in range(3):
                grad[i, a] += lam * g_tw[i, a]
    elif anchor_last:
        theta[ne - 1] = theta_last
        for k in range(nj - 1, -1, -1):
            theta[k] = theta[k + 1] - (mbar[k] - ref[k])
    else:
        theta[0] = theta_first
        for k in range(1 if closed else 0, nj):
            eb = k if closed else k + 1
            theta[eb] = theta[eb - 1] + mbar[k] - ref[k]
    return energy, lam, coef


@nb.njit(cache=True)
def step_batch(x, u_prev, t_prev, rest_len, vlen, ks, alpha, beta, mbar, closed, pos, clamped, anchor_last,
               theta_first, theta_last, total_twist, u, t, theta, grad, ab, g_tw, energy, lam, coef):
    """Run :func:`_step_one` over rods stacked on axis 0 (outputs filled in place).

    closed: rings. clamped: both ends' material frames held (for a ring: its total twist
    ``total_twist`` [rad] imposed). pos: place of each vertex in the band's order,
    shape (n_vertices,)."""
    n_rods, nv = x.shape[0], x.shape[1]
    ref = np.empty(nv)
    le = np.empty(nv)
    ja = np.empty((3, 3))
    jb = np.empty((3, 3))
    hab = np.empty((6, 6))
    for i in range(n_rods):
        e, lm, cf = _step_one(x[i], u_prev[i], t_prev[i], rest_len[i], vlen[i], ks, alpha, beta,
                              mbar[i], closed, pos, clamped, anchor_last, theta_first, theta_last,
                              total_twist, u[i], t[i], theta[i], grad[i], ab[i], g_tw[i], ref, le, ja, jb, hab)
        energy[i] = e
        lam[i] = lm
        coef[i] = cf


@nb.njit(cache=True)
def banded_inverse_band(lb):
    """The entries of A^-1 inside the band of A, from A's lower banded Cholesky factor.

    lb: lower band of L with A = L L^T (scipy.linalg.cholesky_banded(..., lower=True)),
    shape (b + 1, n). Returns zb with zb[d, j] = (A^-1)[j + d, j], shape (b + 1, n).
    Takahashi's recurrence, from the last column to the first: with Lt = L / diag(L),
    Z_ij = -sum_k Lt_kj Z_ik (i > j), Z_jj = 1 / L_jj^2 - sum_k Lt_kj Z_kj, k in (j, j + b].
    """
    bw = lb.shape[0] - 1
    n = lb.shape[1]
    zb = np.zeros_like(lb)
    for j in range(n - 1, -1, -1):
        ljj = lb[0, j]
        kmax = min(bw, n - 1 - j)
        for di in range(kmax, 0, -1):
            i = j + di
            acc = 0.0
            for dk in range(1, kmax + 1):
                k = j + dk
                # Z_ik with i, k > j, |i - k| < bw: stored at zb[|i - k|, min(i, k)].
                zik = zb[i - k, k] if i >= k else zb[k - i, i]
                acc += lb[dk, j] / ljj * zik
            zb[di, j] = -acc
        acc = 0.0
        for dk in range(1, kmax + 1):
            acc += lb[dk, j] / ljj * zb[dk, j]
        zb[0, j] = 1.0 / (ljj * ljj) - acc
    return zb


@nb.njit(cache=True)
def band_cholesky(ab):
    """Lower banded Cholesky factor of a symmetric positive definite matrix.

    ab: lower band, ab[d, j] = A[j + d, j], shape (b + 1, n). Returns lb with
    A = L L^T in the same layout (what scipy.linalg.cholesky_banded(lower=True)
    returns), without the call overhead that dominates for small rods.
    Raises ValueError if A is not positive definite.
    """
    bw = ab.shape[0] - 1
    n = ab.shape[1]
    lb = np.zeros_like(ab)
    for j in range(n):
        acc = ab[0, j]
        for k in range(max(0, j - bw), j):
            ljk = lb[j - k, k]
            acc -= ljk * ljk
        if acc <= 0.0:
            raise ValueError("matrix is not positive definite")
        ljj = math.sqrt(acc)
        lb[0, j] = ljj
        for i in range(j + 1, min(n, j + bw + 1)):
            acc = ab[i - j, j]
            for k in range(max(0, i - bw), j):
                acc -= lb[i - k, k] * lb[j - k, k]
            lb[i - j, j] = acc / ljj
    return lb


@nb.njit(cache=True)
def band_solve(lb, rhs):
    """Solve L L^T x = rhs for a lower banded factor lb (b + 1, n); rhs shape (n, m)."""
    bw = lb.shape[0] - 1
    n, m = rhs.shape
    x = rhs.copy()
    for c in range(m):
        for j in range(n):  # forward: L y = b
            acc = x[j, c]
            for k in range(max(0, j - bw), j):
                acc -= lb[j - k, k] * x[k, c]
            x[j, c] = acc / lb[0, j]
        for j in range(n - 1, -1, -1):  # backward: L^T x = y
            acc = x[j, c]
            for i in range(j + 1, min(n, j + bw + 1)):
                acc -= lb[i - j, j] * x[i, c]
            x[j, c] = acc / lb[0, j]
    return x


@nb.njit(cache=True)
def band_matvec(ab, w):
    """y = A w for symmetric A in lower banded form (b + 1, n); w shape (n,)."""
    bw = ab.shape[0] - 1
    n = ab.shape[1]
    y = np.empty(n)
    for i in range(n):
        y[i] = ab[0, i] * w[i]
    for d in range(1, bw + 1):
        for j in range(n - d):
            y[j + d] += ab[d, j] * w[j]
            y[j] += ab[d, j] * w[j + d]
    return y


@nb.njit(cache=True)
def rows_band(col0, jw, weights, n):
    """Lower band (W, n) of sum_i w_i j_i j_i^T for rows j_i confined to windows
    [col0_i, col0_i + W) with entries jw_i (W = jw.shape[1])."""
    w_ = jw.shape[1]
    out = np.zeros((w_, n))
    for i in range(len(col0)):
        wi = weights[i]
        if wi == 0.0:
            continue
        c0 = col0[i]
        for q in range(w_):
            if c0 + q >= n:
                break
            jq = jw[i, q] * wi
            if jq == 0.0:
                continue
            for p in range(q, w_):
                if c0 + p >= n:
                    break
                out[p - q, c0 + q] += jw[i, p] * jq
    return out


@nb.njit(cache=True)
def rows_diag(col0, jw, zb):
    """j_i^T Z j_i for each windowed row, Z symmetric with lower band zb (>= W rows)."""
    w_ = jw.shape[1]
    n = zb.shape[1]
    out = np.zeros(len(col0))
    for i in range(len(col0)):
        c0 = col0[i]
        acc = 0.0
        for q in range(w_):
            if c0 + q >= n:
                break
            jq = jw[i, q]
            if jq == 0.0:
                continue
            acc += jq * jq * zb[0, c0 + q]
            for p in range(q + 1, w_):
                if c0 + p >= n:
                    break
                acc += 2.0 * jw[i, p] * jq * zb[p - q, c0 + q]
        out[i] = acc
    return out


@nb.njit(cache=True)
def rows_apply(col0, jw, a):
    """J a for rows confined to windows [col0_i, col0_i + W) with entries jw_i; shape (k,)."""
    n = a.shape[0]
    out = np.zeros(len(col0))
    for i in range(len(col0)):
        c0 = col0[i]
        acc = 0.0
        for q in range(min(jw.shape[1], n - c0)):
            acc += jw[i, q] * a[c0 + q]
        out[i] = acc
    return out


@nb.njit(cache=True)
def rows_transpose_apply(col0, jw, lam, n):
    """J^T lam for windowed rows (as :func:`rows_apply`); shape (n,)."""
    out = np.zeros(n)
    for i in range(len(col0)):
        c0 = col0[i]
        for q in range(min(jw.shape[1], n - c0)):
            out[c0 + q] += jw[i, q] * lam[i]
    return out


@nb.njit(cache=True)
def exact_line_search(jar, jd, d, d_a, d_g, max_iter=20):
    """Step t minimizing f(t) = t^2 d_a / 2 + t d_g + sum_i d_i min(jar_i + t jd_i, 0)^2 / 2
    by Newton's method on the piecewise linear, increasing f'(t), from t = 1."""
    t = 1.0
    for _ in range(max_iter):
        fp = t * d_a + d_g
        fpp = d_a
        for i in range(len(jar)):
            r = jar[i] + t * jd[i]
            if r < 0.0:
                fp += d[i] * r * jd[i]
                fpp += d[i] * jd[i] * jd[i]
        step = fp / fpp
        t -= step
        if abs(step) <= 1e-12 * max(1.0, abs(t)):
            break
    return t


@nb.njit(cache=True)
def sparse_triplets(rownnz, rowadr, colind, values):
    """(row, col, value) of every nonzero of a CSR matrix (MuJoCo's sparse efc_J)."""
    total = 0
    for r in range(len(rownnz)):
        total += rownnz[r]
    row = np.empty(total, dtype=np.int64)
    col = np.empty(total, dtype=np.int64)
    val = np.empty(total)
    p = 0
    for r in range(len(rownnz)):
        for q in range(rownnz[r]):
            row[p] = r
            col[p] = colind[rowadr[r] + q]
            val[p] = values[rowadr[r] + q]
            p += 1
    return row, col, val


@nb.njit(cache=True)
def split_rows(row, col, val, local_of_dof, supported, force, n, width):
    """Sort constraint rows that touch rod dofs (see :func:`derods.contact.rod_rows`).

    row, col, val: the nonzeros of MuJoCo's efc_J; local_of_dof (nv,): local rod dof or -1;
    supported (nefc,): rows derods can solve; force (nefc,): MuJoCo's row forces; n: local
    dofs; width: window of a banded row. A row is derods' if it touches only rod dofs and is
    supported; its force is MuJoCo's otherwise (returned as ext on the local dofs).
    Returns (efc: derods' rows, banded first; kb: how many are banded; col0 (kb,);
    jw (kb, width); jf (k - kb, n); ext (n,)).
    """
    nefc = len(supported)
    touches = np.zeros(nefc, dtype=np.bool_)
    elsewhere = np.zeros(nefc, dtype=np.bool_)
    lo = np.full(nefc, np.iinfo(np.int64).max)
    hi = np.full(nefc, -1)
    for p in range(len(row)):
        r = row[p]
        loc = local_of_dof[col[p]]
        if loc >= 0:
            touches[r] = True
            lo[r] = min(lo[r], loc)
            hi[r] = max(hi[r], loc)
        else:
            elsewhere[r] = True
    mine = touches & ~elsewhere & supported
    ext = np.zeros(n)
    for p in range(len(row)):
        r = row[p]
        loc = local_of_dof[col[p]]
        if loc >= 0 and touches[r] and not mine[r]:
            ext[loc] += val[p] * force[r]
    banded = mine & (hi - lo < width)
    far = mine & ~banded
    efc = np.concatenate((np.flatnonzero(banded), np.flatnonzero(far)))
    kb = int(banded.sum())
    k_of_row = np.full(nefc, -1)
    for k in range(len(efc)):
        k_of_row[efc[k]] = k
    jw = np.zeros((kb, width))
    jf = np.zeros((len(efc) - kb, n))
    for p in range(len(row)):
        k = k_of_row[row[p]]
        loc = local_of_dof[col[p]]
        if k < 0 or loc < 0:
            continue
        if k < kb:
            jw[k, loc - lo[row[p]]] = val[p]
        else:
            jf[k - kb, loc] = val[p]
    col0 = lo[efc[:kb]].copy()
    return efc, kb, col0, jw, jf, ext
