"""Compiled bending in material curvatures, with the twist solved by Newton's method:
anisotropic and naturally curved rods (the numpy path is :meth:`derods.Rod.step_terms`
with ``use_kernel=False``: :func:`derods.energy.bend_material`, :func:`derods.energy.twist`
and :func:`derods.twist.solve_newton`, which tests/test_step.py holds this to).

E = sum_k [ sum_{s, c} B_c / (2 l_k) (omega_k^s_c - omegabar_k^s_c)^2 + beta / l_k (m_k - mbar_k)^2 ]
(Bergou et al. 2008, eqs. 5-6), omega^s = (kb . m2^s, -kb . m1^s) in the material
frame of the joint's edge s (s = 0 before, 1 after), m_k = theta^b - theta^a + ref_k
(+ a ring's total twist at its seam joint 0); kb is the rod's measure of bending, Bergou's
or the turning angle's (:func:`derods._numba.rod_geometry.turning_angle`), while the
reference twist's gradient keeps Bergou's kb. The twist angles minimize E at
fixed centerline (damped Newton on the tridiagonal, on a ring cyclic, theta
Hessian, with a backtracking line search); then the gradient in x and the
Gauss-Newton Hessian at fixed theta (which overestimates the stiffness a relaxing
frame leaves: more damping in the implicit step, never less stability).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from .banded import cholesky_ok, solve_into
from .rod_geometry import add_joint_hessian, curvature_binormal, joint_stencil, reference_twist, turning_angle

#: Newton on the twist angles: stop when the largest free gradient entry is below TOL times
#: the largest diagonal entry of the theta Hessian. The line search accepts a step whose
#: energy rises by at most SLACK times the energy: a sum of squares that round-off resolves
#: to ~1e-16 of itself, so near the solution a full Newton step is taken (and converges
#: quadratically) instead of being halved to nothing; a search that still finds no step
#: ends the solve (as derods.twist.solve_newton does).
TOL = 1e-10
SLACK = 1e-14
MAX_ITER = 50


class FixedCenterline(NamedTuple):
    """A rod's twist problem at a fixed centerline, E(theta) in the module's formula: its
    reference directors u and tangents t (n_edges, 3); per joint, the curvature binormal kb
    it bends by (n_joints, 3), the reference twist ref_twist [rad], the vertex length vlen [m], the
    natural twist mbar [rad] and the rest material curvatures wbar (n_joints, 2, 2); the
    principal bending stiffnesses b1, b2 and the twist stiffness beta [N m^2]; closed; a
    ring's imposed twist at its seam joint, offset [rad] (0 for an open rod)."""

    u: np.ndarray
    t: np.ndarray
    kb: np.ndarray
    ref_twist: np.ndarray
    vlen: np.ndarray
    mbar: np.ndarray
    wbar: np.ndarray
    b1: float
    b2: float
    beta: float
    closed: bool
    offset: float


@nb.njit(cache=True, inline="always")
def _omega(kb0, kb1, kb2, u, t, theta, e):
    """Material curvatures (kb . m2, -kb . m1) of edge e's frame at angle theta[e]."""
    c, s = math.cos(theta[e]), math.sin(theta[e])
    u0, u1, u2 = u[e, 0], u[e, 1], u[e, 2]
    t0, t1, t2 = t[e, 0], t[e, 1], t[e, 2]
    v0, v1, v2 = t1 * u2 - t2 * u1, t2 * u0 - t0 * u2, t0 * u1 - t1 * u0
    m10, m11, m12 = c * u0 + s * v0, c * u1 + s * v1, c * u2 + s * v2
    m20, m21, m22 = c * v0 - s * u0, c * v1 - s * u1, c * v2 - s * u2
    return kb0 * m20 + kb1 * m21 + kb2 * m22, -(kb0 * m10 + kb1 * m11 + kb2 * m12), m10, m11, m12, m20, m21, m22


@nb.njit(cache=True)
def _theta_energy(rod, theta, order, g, hd, ho):
    """E(theta) of ``rod`` (:class:`FixedCenterline`), and (order >= 1) dE/dtheta into g
    (n_edges,), (order 2) the theta Hessian: diagonal hd (n_edges,), joint k's coupling of
    its two edges ho (n_joints,)."""
    u, t, kbs, ref, vlen, mbar, wbar = rod.u, rod.t, rod.kb, rod.ref_twist, rod.vlen, rod.mbar, rod.wbar
    b1, b2, beta, closed, offset = rod.b1, rod.b2, rod.beta, rod.closed, rod.offset
    ne = t.shape[0]
    nj = kbs.shape[0]
    nv = ne if closed else ne + 1
    if order >= 1:
        g[:] = 0.0
    if order >= 2:
        hd[:] = 0.0
        ho[:] = 0.0
    energy = 0.0
    for k in range(nj):
        ea, eb, _, _, _ = joint_stencil(k, closed, ne, nv)
        bl0, bl1 = b1 / vlen[k], b2 / vlen[k]
        for side in range(2):
            e = ea if side == 0 else eb
            w0, w1, _, _, _, _, _, _ = _omega(kbs[k, 0], kbs[k, 1], kbs[k, 2], u, t, theta, e)
            d0, d1 = w0 - wbar[k, side, 0], w1 - wbar[k, side, 1]
            energy += 0.5 * (bl0 * d0 * d0 + bl1 * d1 * d1)
            if order >= 1:
                r0, r1 = bl0 * d0, bl1 * d1
                # d omega / d theta: (omega_1, -omega_0)
                g[e] += r0 * w1 - r1 * w0
                if order >= 2:
                    hd[e] += bl0 * w1 * w1 + bl1 * w0 * w0 - (r0 * w0 + r1 * w1)
        m = theta[eb] - theta[ea] + ref[k] + (offset if (closed and k == 0) else 0.0)
        dm = m - mbar[k]
        cb = beta / vlen[k]
        energy += cb * dm * dm
        if order >= 1:
            sg = 2.0 * cb * dm
            g[ea] -= sg
            g[eb] += sg
        if order >= 2:
            hd[ea] += 2.0 * cb
            hd[eb] += 2.0 * cb
            ho[k] -= 2.0 * cb
    return energy


@nb.njit(cache=True)
def _newton_theta(rod, theta, lo, hi, pos):
    """Minimize E of ``rod`` (:class:`FixedCenterline`) over the free angles theta[lo:hi]
    (a ring: all). Edge e is unknown pos[e] - lo of the system: an open rod in order (a
    tridiagonal Hessian), a ring in its zig-zag order (its cyclic Hessian is then banded, two
    sub-diagonals). Levenberg-Marquardt damping where the Hessian is not positive definite,
    backtracking on the energy."""
    closed = rod.closed
    ne = rod.t.shape[0]
    nj = rod.kb.shape[0]
    m = hi - lo
    g = np.empty(ne)
    hd = np.empty(ne)
    ho = np.empty(nj)
    trial = np.empty(ne)
    step = np.empty(m)
    rows = 3 if closed else 2
    ab = np.zeros((rows, m))
    lt = np.zeros((m, rows))
    mu = 0.0
    for _ in range(MAX_ITER):
        e0 = _theta_energy(rod, theta, 2, g, hd, ho)
        scale = 0.0
        gmax = 0.0
        for e in range(lo, hi):
            scale = max(scale, abs(hd[e]))
            gmax = max(gmax, abs(g[e]))
        scale = max(scale, 1e-300)
        if gmax <= TOL * scale:
            break
        while True:
            ab[:] = 0.0
            for e in range(lo, hi):
                ab[0, pos[e] - lo] += hd[e] + mu * scale
            for k in range(nj):
                ea = (k - 1) % ne if closed else k
                eb = k if closed else k + 1
                if ea < lo or eb >= hi:
                    continue  # a held angle: no coupling in the free system
                pa, pb = pos[ea] - lo, pos[eb] - lo
                r, c = (pa, pb) if pa > pb else (pb, pa)
                ab[r - c, c] += ho[k]
            if cholesky_ok(ab, lt):
                break
            mu = max(1e-12, 10.0 * mu)
        for e in range(lo, hi):
            step[pos[e] - lo] = -g[e]
        solve_into(lt, step, 0, m)
        gs = 0.0
        for e in range(lo, hi):
            gs += g[e] * step[pos[e] - lo]
        s = 1.0
        while True:
            trial[:] = theta
            for e in range(lo, hi):
                trial[e] += s * step[pos[e] - lo]
            e1 = _theta_energy(rod, trial, 0, g, hd, ho)
            if e1 <= e0 + 1e-4 * s * gs + SLACK * abs(e0) or s < 1e-8:
                break
            s *= 0.5
        if s < 1e-8:
            break  # no descent left to find: round-off rules the energy
        theta[:] = trial
        mu = mu * 0.1 if mu > 1e-12 else 0.0


@nb.njit(cache=True)
def material_rod(rods, i, t, u, theta, theta_first, theta_last, place, grad, ab, work):
    """Bending in material curvatures and the twist (solved by Newton) of rod i of ``rods``
    (:class:`derods.step.RodSet`), after :func:`derods._numba.rod_geometry.edges`: t, u,
    theta, place, grad are the rod's slices, theta_first, theta_last [rad] its held end
    angles this step, ab its band, work a :class:`derods._numba.rod_geometry.Scratch`
    (edge_len filled by edges). Adds to grad [N] and the band [N/m]; writes theta [rad].
    The rod's edge_pos: each edge's place in the twist system (identity for an open rod,
    the zig-zag order for a ring). Returns (energy [J], dE/dtheta of the first and last
    edge [N m]: the moments held ends resist)."""
    j0, j1, e0 = rods.j_off[i], rods.j_off[i + 1], rods.e_off[i]
    vlen, mbar, wbar = rods.vlen[j0:j1], rods.mbar[j0:j1], rods.wbar[j0:j1]
    b1, b2, beta, closed, angle = rods.bend[i, 0], rods.bend[i, 1], rods.beta[i], rods.closed[i], rods.turning_angle[i]
    fix_first, fix_last, total_twist = rods.fix_first[i], rods.fix_last[i], rods.total_twist[i]
    edge_pos = rods.edge_pos[e0:rods.e_off[i + 1]]
    le, kbs, ref = work.edge_len, work.kb, work.ref_twist
    ja, jb, h6, blocks = work.jac_a, work.jac_b, work.h6, work.blocks
    nv = grad.shape[0]
    ne = nv if closed else nv - 1
    nj = nv if closed else nv - 2
    kbs, ref = kbs[:nj], ref[:nj]  # scratch arrays sized for the longest rod
    for k in range(nj):
        ea, eb, _, _, _ = joint_stencil(k, closed, ne, nv)
        kb0, kb1, kb2, chi = curvature_binormal(t, le, ea, eb, ja, jb)
        if angle:
            kb0, kb1, kb2 = turning_angle(kb0, kb1, kb2, ja, jb)
        kbs[k, 0], kbs[k, 1], kbs[k, 2] = kb0, kb1, kb2
        ref[k] = reference_twist(u, t, ea, eb, chi)
    lo, hi = 0, ne
    if fix_first:
        theta[0] = theta_first
        lo = 1
    if fix_last:
        theta[ne - 1] = theta_last
        hi = ne - 1
    offset = total_twist if closed else 0.0
    rod = FixedCenterline(u, t, kbs, ref, vlen, mbar, wbar, b1, b2, beta, closed, offset)
    if hi > lo:
        _newton_theta(rod, theta, lo, hi, edge_pos)
    g = np.empty(ne)
    _theta_energy(rod, theta, 1, g, g, g[:0])
    # Gradient in x and the Gauss-Newton Hessian at the solved angles.
    energy = 0.0
    n_sc = np.empty((2, 2, 3))
    w_g = np.empty(3)
    jn = np.empty(6)
    gr = np.empty(6)
    for k in range(nj):
        ea, eb, va, vm, vn = joint_stencil(k, closed, ne, nv)
        kb0, kb1, kb2, chi = curvature_binormal(t, le, ea, eb, ja, jb)
        # bk: the curvature the rod bends by (ja, jb become its Jacobians); kb stays for the twist.
        bk0, bk1, bk2 = turning_angle(kb0, kb1, kb2, ja, jb) if angle else (kb0, kb1, kb2)
        bl = (b1 / vlen[k], b2 / vlen[k])
        w_g[:] = 0.0
        for r in range(6):
            for c in range(6):
                h6[r, c] = 0.0
        for side in range(2):
            e = ea if side == 0 else eb
            w0, w1, m10, m11, m12, m20, m21, m22 = _omega(bk0, bk1, bk2, u, t, theta, e)
            # omega_s0 = kb . n_s0 with n_s0 = m2, omega_s1 = kb . n_s1 with n_s1 = -m1.
            n_sc[side, 0, 0], n_sc[side, 0, 1], n_sc[side, 0, 2] = m20, m21, m22
            n_sc[side, 1, 0], n_sc[side, 1, 1], n_sc[side, 1, 2] = -m10, -m11, -m12
            for c in range(2):
                d = (w0 if c == 0 else w1) - wbar[k, side, c]
                energy += 0.5 * bl[c] * d * d
                r = bl[c] * d
                for a in range(3):
                    w_g[a] += r * n_sc[side, c, a]
                # jn = J^T n_sc over (a, b): d omega_sc / d(e_a, e_b).
                for q in range(3):
                    jn[q] = ja[0, q] * n_sc[side, c, 0] + ja[1, q] * n_sc[side, c, 1] + ja[2, q] * n_sc[side, c, 2]
                    jn[q + 3] = (jb[0, q] * n_sc[side, c, 0] + jb[1, q] * n_sc[side, c, 1]
                                 + jb[2, q] * n_sc[side, c, 2])
                for p in range(6):
                    for q in range(6):
                        h6[p, q] += bl[c] * jn[p] * jn[q]
        for c in range(3):
            ga = ja[0, c] * w_g[0] + ja[1, c] * w_g[1] + ja[2, c] * w_g[2]
            gb = jb[0, c] * w_g[0] + jb[1, c] * w_g[1] + jb[2, c] * w_g[2]
            grad[va, c] -= ga
            grad[vm, c] += ga - gb
            grad[vn, c] += gb
        # The twist term at the solved angles: dE/dx = s g_r, PSD Hessian 2 c g_r g_r^T.
        m = theta[eb] - theta[ea] + ref[k] + (offset if (closed and k == 0) else 0.0)
        dm = m - mbar[k]
        cb = beta / vlen[k]
        energy += cb * dm * dm
        sg = 2.0 * cb * dm
        gr[0], gr[1], gr[2] = kb0 / (2.0 * le[ea]), kb1 / (2.0 * le[ea]), kb2 / (2.0 * le[ea])
        gr[3], gr[4], gr[5] = kb0 / (2.0 * le[eb]), kb1 / (2.0 * le[eb]), kb2 / (2.0 * le[eb])
        for c in range(3):
            grad[va, c] -= sg * gr[c]
            grad[vm, c] += sg * (gr[c] - gr[c + 3])
            grad[vn, c] += sg * gr[c + 3]
        for p in range(6):
            for q in range(6):
                h6[p, q] += 2.0 * cb * gr[p] * gr[q]
        add_joint_hessian(ab, place, va, vm, vn, h6, blocks)
    return energy, g[0], g[ne - 1]
