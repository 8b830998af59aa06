"""Compiled mirror of :mod:`derods.step`: one step's terms for a set of isotropic,
naturally straight rods of any sizes, in one call.

For every rod: transport the reference frames in time, turn the frames of
clamps held by moving bodies, solve the quasistatic twist, and evaluate the
gradient and the positive semi-definite banded Hessian of stretch + isotropic
bending + the reduced twist. At a few hundred vertices a numpy call costs
more in overhead than in arithmetic; this kernel removes that overhead, and
one call serves every rod of a world (rods are laid end to end in flat
arrays, see :class:`derods.step.RodSet`).

Open rods and rings share one loop: edge j joins vertices j and j + 1 (mod n
on a ring); joint k joins edges k, k + 1 of an open rod and k - 1, k of a ring
(:func:`derods.geometry.joint_pairs`). The Hessian is written into one lower
band over the places given by ``place`` (a vertex's place in the solve order,
-1 for a vertex that is held and has no dofs). tests/test_step.py checks this
kernel against the numpy path, which is checked against finite differences.

Formulas and conventions are those of :mod:`derods.energy`,
:mod:`derods.frames` and :mod:`derods.twist`; the lower banded layout is that
of :mod:`derods.stencil`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..geometry import CHI_MIN


@nb.njit(cache=True, inline="always")
def _add_block(ab, place, vi, vj, blk):
    """Add the 3 x 3 block blk to H[vertex vi, vertex vj] of a symmetric matrix kept as
    its lower band, the vertices at places p = place[v] of the solve order (nothing for a
    held vertex, place -1). Of a diagonal block (vi == vj) only the lower triangle is
    added; an off-diagonal block lands in the lower half, transposed if its vertices come
    in the other order (each such block is added for one order only)."""
    pi_, pj = place[vi], place[vj]
    if pi_ < 0 or pj < 0:
        return
    if abs(pi_ - pj) * 3 + 2 >= ab.shape[0]:
        raise ValueError("a Hessian entry falls outside the band; check the vertex order")
    if pi_ > pj:
        for r in range(3):
            for c in range(3):
                ab[3 * (pi_ - pj) + r - c, 3 * pj + c] += blk[r, c]
    elif pi_ == pj:
        for r in range(3):
            for c in range(r + 1):
                ab[r - c, 3 * pj + c] += blk[r, c]
    else:
        for r in range(3):
            for c in range(3):
                ab[3 * (pj - pi_) + c - r, 3 * pi_ + r] += blk[r, c]


@nb.njit(cache=True)
def _rod_step(x, u, t, theta, rest_len, vlen, mbar, ks, alpha, beta, closed, has_twist, clamped, anchor_last,
              theta_first, theta_last, total_twist, clamp_body, clamp_dir, theta_end, xmat, place, grad, ab,
              g_tw, ref, le, ja, jb, blocks):
    """One rod (arrays are this rod's slices; u, t, theta updated in place). Returns
    (energy [J], twisting moment lam [N m], twist stiffness c [N m], largest |strain|)."""
    nv = x.shape[0]
    ne = nv if closed else nv - 1
    nj = nv if closed else nv - 2
    energy = 0.0
    max_strain = 0.0
    for i in range(nv):
        for a in range(3):
            grad[i, a] = 0.0
            g_tw[i, a] = 0.0
    # Edges: tangents, time-parallel transport of the reference frames, stretching.
    for j in range(ne):
        jn = (j + 1) % nv
        e0 = x[jn, 0] - x[j, 0]
        e1 = x[jn, 1] - x[j, 1]
        e2 = x[jn, 2] - x[j, 2]
        lj = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        le[j] = lj
        c0, c1, c2 = e0 / lj, e1 / lj, e2 / lj
        p0, p1, p2 = t[j, 0], t[j, 1], t[j, 2]
        t[j, 0], t[j, 1], t[j, 2] = c0, c1, c2
        k0, k1, k2 = p1 * c2 - p2 * c1, p2 * c0 - p0 * c2, p0 * c1 - p1 * c0
        s0, s1, s2 = p0 + c0, p1 + c1, p2 + c2
        opc = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
        cc = opc - 1.0
        w0, w1, w2 = u[j, 0], u[j, 1], u[j, 2]
        kw = (k0 * w0 + k1 * w1 + k2 * w2) / opc
        v0 = cc * w0 + (k1 * w2 - k2 * w1) + k0 * kw
        v1 = cc * w1 + (k2 * w0 - k0 * w2) + k1 * kw
        v2 = cc * w2 + (k0 * w1 - k1 * w0) + k2 * kw
        vt = v0 * c0 + v1 * c1 + v2 * c2
        v0, v1, v2 = v0 - vt * c0, v1 - vt * c1, v2 - vt * c2
        nvv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        u[j, 0], u[j, 1], u[j, 2] = v0 / nvv, v1 / nvv, v2 / nvv
        strain = lj / rest_len[j] - 1.0
        # NaN compares false: a NaN strain becomes the "largest" so the check sees it.
        if not abs(strain) <= max_strain:
            max_strain = abs(strain) if abs(strain) == abs(strain) else np.inf
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
                blocks[0, r, c] = h
                blocks[1, r, c] = -h
        _add_block(ab, place, j, j, blocks[0])
        _add_block(ab, place, jn, jn, blocks[0])
        _add_block(ab, place, jn, j, blocks[1])
    # Clamps on moving bodies: the clamped edge's material director turns with its body;
    # its angle from the transported reference director, unwrapped over many turns.
    for end in range(2):
        b = clamp_body[end]
        if b < 0:
            continue
        edge = 0 if end == 0 else ne - 1
        d0 = xmat[b, 0] * clamp_dir[end, 0] + xmat[b, 1] * clamp_dir[end, 1] + xmat[b, 2] * clamp_dir[end, 2]
        d1 = xmat[b, 3] * clamp_dir[end, 0] + xmat[b, 4] * clamp_dir[end, 1] + xmat[b, 5] * clamp_dir[end, 2]
        d2 = xmat[b, 6] * clamp_dir[end, 0] + xmat[b, 7] * clamp_dir[end, 1] + xmat[b, 8] * clamp_dir[end, 2]
        w0, w1, w2 = u[edge, 0], u[edge, 1], u[edge, 2]
        sin_ = (w1 * d2 - w2 * d1) * t[edge, 0] + (w2 * d0 - w0 * d2) * t[edge, 1] + (w0 * d1 - w1 * d0) * t[edge, 2]
        angle = math.atan2(sin_, w0 * d0 + w1 * d1 + w2 * d2)
        prev = theta_end[end]
        theta_end[end] = prev + (angle - prev + np.pi) % (2 * np.pi) - np.pi
        if end == 0:
            theta_first = theta_end[end]
        else:
            theta_last = theta_end[end]
    # Joints: isotropic bending, and the reference twist with its gradient.
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
        for r in range(3):
            for c in range(3):
                haa = two_c * (ja[0, r] * ja[0, c] + ja[1, r] * ja[1, c] + ja[2, r] * ja[2, c])
                hab_ = two_c * (ja[0, r] * jb[0, c] + ja[1, r] * jb[1, c] + ja[2, r] * jb[2, c])
                hba = two_c * (jb[0, r] * ja[0, c] + jb[1, r] * ja[1, c] + jb[2, r] * ja[2, c])
                hbb = two_c * (jb[0, r] * jb[0, c] + jb[1, r] * jb[1, c] + jb[2, r] * jb[2, c])
                blocks[0, r, c] = haa
                blocks[1, r, c] = haa - hab_ - hba + hbb
                blocks[2, r, c] = hbb
                blocks[3, r, c] = hba - haa
                blocks[4, r, c] = hba - hbb
                blocks[5, r, c] = -hba
        _add_block(ab, place, va, va, blocks[0])
        _add_block(ab, place, vm, vm, blocks[1])
        _add_block(ab, place, vn, vn, blocks[2])
        _add_block(ab, place, vm, va, blocks[3])
        _add_block(ab, place, vn, vm, blocks[4])
        _add_block(ab, place, vn, va, blocks[5])
        if not has_twist:
            continue
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
    lam = 0.0
    coef = 0.0
    if not has_twist:
        return energy, lam, coef, max_strain
    # Quasistatic twist (closed form, see derods.twist.solve_isotropic): theta of edge eb
    # follows theta of edge ea by d_k + mbar_k - ref_k across joint k (not across a ring's seam).
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
    return energy, lam, coef, max_strain


@nb.njit(cache=True)
def rods_step(x, v_off, e_off, j_off, rest_len, vlen, mbar, ks, alpha, beta, compiled, closed, has_twist, clamped,
              anchor_last, theta_first, theta_last, total_twist, clamp_body, clamp_dir, theta_end, xmat,
              place, band_of_rod, u, t, theta, grad, bands, g_tw, energy, lam, coef, strain):
    """Every rod of a set, laid end to end (see :class:`derods.step.RodSet` for the
    per-rod arguments). In: positions x (n_vertices, 3) [m]; the previous frames u, t
    (n_edges, 3) and twist angles theta (n_edges,), updated in place; theta_end (n_rods, 2)
    [rad], the unwrapped angles of clamps on moving bodies, updated in place; xmat
    (n_bodies, 9), MuJoCo's body orientations. Out: grad (n_vertices, 3) [N]; bands
    (n_bands, rows, n_dofs), lower bands of the PSD Hessian [N/m], zeroed here first: rod
    i adds to bands[band_of_rod[i]] at its vertices' places ``place`` (n_vertices,) (one
    band for all rods in a world; one per rod for :meth:`derods.Rod.step_terms`); g_tw
    (n_vertices, 3) [1/m], the reduced twist term's direction; energy, lam, coef, strain
    per rod. Returns the first rod whose largest |strain| is not finite or exceeds
    ``strain`` on entry, else -1 (strain (n_rods,): limit in, value out)."""
    n_rods = len(v_off) - 1
    max_nv = 0
    for i in range(n_rods):
        max_nv = max(max_nv, v_off[i + 1] - v_off[i])
    ref = np.empty(max_nv)
    le = np.empty(max_nv)
    ja = np.empty((3, 3))
    jb = np.empty((3, 3))
    blocks = np.empty((6, 3, 3))
    bands[:] = 0.0
    first_bad = -1
    for i in range(n_rods):
        if not compiled[i]:
            continue
        v0, v1 = v_off[i], v_off[i + 1]
        e0, e1 = e_off[i], e_off[i + 1]
        j0, j1 = j_off[i], j_off[i + 1]
        e, lm, cf, st = _rod_step(
            x[v0:v1], u[e0:e1], t[e0:e1], theta[e0:e1], rest_len[e0:e1], vlen[j0:j1], mbar[j0:j1], ks[i],
            alpha[i], beta[i], closed[i], has_twist[i], clamped[i], anchor_last[i], theta_first[i],
            theta_last[i], total_twist[i], clamp_body[i], clamp_dir[i], theta_end[i], xmat, place[v0:v1],
            grad[v0:v1], bands[band_of_rod[i]], g_tw[v0:v1], ref, le, ja, jb, blocks)
        energy[i] = e
        lam[i] = lm
        coef[i] = cf
        if first_bad < 0 and not st <= strain[i]:
            first_bad = i
        strain[i] = st
    return first_bad
