"""What every compiled rod step shares: band writes, edges (transport, stretching), clamps
turned with their bodies, and a joint's curvature binormal with its Jacobians (Bergou's kb,
or the turning angle's, :func:`turning_angle`).

Conventions are those of :mod:`derods.geometry` and :mod:`derods.frames`: edge j
joins vertices j and j + 1 (mod n on a ring); joint k joins edges k, k + 1 of an
open rod and k - 1, k of a ring. The Hessian is kept as one lower band over the
vertices' places in the solve order (``place``, -1 for a held vertex).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..geometry import ANGLE_SERIES_MAX, ANGLE_SERIES_TERMS, CHI_MIN
from .leaf import leaf


class Scratch(NamedTuple):
    """Work arrays of a rod's joints, sized for the longest rod of a set (n vertices):
    edge_len (n,) [m], the edges' lengths; ref_twist (n,) [rad], the joints' reference
    twists; kb (n, 3), their curvature binormals; jac_a, jac_b (3, 3), a joint's Jacobians
    of kb; h6 (6, 6), its Hessian; blocks (6, 3, 3), that Hessian's blocks per vertex pair."""

    edge_len: np.ndarray
    ref_twist: np.ndarray
    kb: np.ndarray
    jac_a: np.ndarray
    jac_b: np.ndarray
    h6: np.ndarray
    blocks: np.ndarray


@nb.njit(cache=True, inline="always")
def transport(p0, p1, p2, c0, c1, c2, w0, w1, w2):
    """The parallel transport of w from unit tangent p to unit tangent c, made
    perpendicular to c and unit (the formula of :func:`derods.frames.parallel_transport`,
    chi floored at CHI_MIN); returns its three components."""
    k0, k1, k2 = p1 * c2 - p2 * c1, p2 * c0 - p0 * c2, p0 * c1 - p1 * c0
    s0, s1, s2 = p0 + c0, p1 + c1, p2 + c2
    opc = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
    cc = opc - 1.0
    kw = (k0 * w0 + k1 * w1 + k2 * w2) / opc
    v0 = cc * w0 + (k1 * w2 - k2 * w1) + k0 * kw
    v1 = cc * w1 + (k2 * w0 - k0 * w2) + k1 * kw
    v2 = cc * w2 + (k0 * w1 - k1 * w0) + k2 * kw
    vt = v0 * c0 + v1 * c1 + v2 * c2
    v0, v1, v2 = v0 - vt * c0, v1 - vt * c1, v2 - vt * c2
    nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    return v0 / nv, v1 / nv, v2 / nv


@nb.njit(cache=True, inline="always")
def add_block(ab, place, vi, vj, blk):
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


@nb.njit(cache=True, inline="always")
def joint_stencil(k, closed, ne, nv):
    """(ea, eb, va, vm, vn): joint k's edges and its three vertices (vm between them)."""
    if closed:
        return (k - 1) % ne, k, (k - 1) % nv, k, (k + 1) % nv
    return k, k + 1, k, k + 1, k + 2


@nb.njit(cache=True)
def edges(x, u, t, rest_len, ks, closed, place, grad, ab, le, blocks):
    """Tangents, the time-parallel transport of the reference frames, and stretching.

    Transports u from the old tangents t to the new ones (both updated in place), writes
    the edge lengths le, zeroes grad and adds the stretching gradient [N] and PSD Hessian
    [N/m] (tension's geometric stiffness clamped at 0). Returns (energy [J], largest
    |strain|, inf if a strain is not finite)."""
    nv = x.shape[0]
    ne = nv if closed else nv - 1
    energy = 0.0
    max_strain = 0.0
    for i in range(nv):
        for a in range(3):
            grad[i, a] = 0.0
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
        u[j, 0], u[j, 1], u[j, 2] = transport(p0, p1, p2, c0, c1, c2, u[j, 0], u[j, 1], u[j, 2])
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
        add_block(ab, place, j, j, blocks[0])
        add_block(ab, place, jn, jn, blocks[0])
        add_block(ab, place, jn, j, blocks[1])
    return energy, max_strain


@nb.njit(cache=True)
def turn_clamps(u, t, ne, clamp_body, clamp_dir, theta_end, xmat, theta_first, theta_last):
    """Clamps on moving bodies: each clamped end edge's material director turns with its
    body (director clamp_dir in the body frame, orientation xmat); its angle from the
    transported reference director, unwrapped over many turns (theta_end, updated),
    replaces that end's held angle. Returns (theta_first, theta_last) [rad]."""
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
    return theta_first, theta_last


@nb.njit(cache=True)
def curvature_binormal(t, le, ea, eb, ja, jb):
    """kb of the joint between edges ea, eb (Bergou et al. 2008, eq. 1), and its
    Jacobians ja = d kb / d e_a, jb = d kb / d e_b (3 x 3, written into ja, jb):
    ja = (-2 [tb]x - kb s^T) / (la chi), jb = (2 [ta]x - kb s^T) / (lb chi), s = ta + tb.
    Returns (kb0, kb1, kb2, chi)."""
    a0, a1, a2 = t[ea, 0], t[ea, 1], t[ea, 2]
    b0, b1, b2 = t[eb, 0], t[eb, 1], t[eb, 2]
    la, lb = le[ea], le[eb]
    s0, s1, s2 = a0 + b0, a1 + b1, a2 + b2
    chi = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
    kb0 = 2.0 * (a1 * b2 - a2 * b1) / chi
    kb1 = 2.0 * (a2 * b0 - a0 * b2) / chi
    kb2 = 2.0 * (a0 * b1 - a1 * b0) / chi
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
    return kb0, kb1, kb2, chi


@nb.njit(cache=True)
def turning_angle(kb0, kb1, kb2, ja, jb):
    """A joint's turning-angle curvature from Bergou's kb and its Jacobians ja, jb (as
    :func:`curvature_binormal` leaves them; :class:`derods.geometry.TurningAngle`):
    kb_angle = g kb, g = 2 atan(x / 2) / x, x = |kb|, so |kb_angle| = phi [rad]; ja, jb are
    overwritten by G ja, G jb, G = d kb_angle / d kb = g I + a kb kb^T, a = g' / x (the
    factors of :func:`derods.geometry.turning_angle_factors`, series below ANGLE_SERIES_MAX).
    Returns kb_angle's three components."""
    y = 0.25 * (kb0 * kb0 + kb1 * kb1 + kb2 * kb2)
    if 4.0 * y < ANGLE_SERIES_MAX * ANGLE_SERIES_MAX:
        g = 0.0
        a = 0.0
        for m in range(ANGLE_SERIES_TERMS, -1, -1):  # Horner, from the highest power of y
            sign = -1.0 if m % 2 else 1.0
            g = g * y + sign / (2 * m + 1)
            if m >= 1:
                a = a * y + sign * m / (2 * m + 1)
        a = 0.5 * a
    else:
        root = math.sqrt(y)
        g = math.atan(root) / root
        a = (1.0 / (1.0 + y) - g) / (4.0 * y)
    kbv = (kb0, kb1, kb2)
    for c in range(3):
        sa = kb0 * ja[0, c] + kb1 * ja[1, c] + kb2 * ja[2, c]
        sb = kb0 * jb[0, c] + kb1 * jb[1, c] + kb2 * jb[2, c]
        for r in range(3):
            ja[r, c] = g * ja[r, c] + a * kbv[r] * sa
            jb[r, c] = g * jb[r, c] + a * kbv[r] * sb
    return g * kb0, g * kb1, g * kb2


@nb.njit(cache=True)
def reference_twist(u, t, ea, eb, chi):
    """The joint's reference twist [rad]: the angle about tb from the space-parallel
    transport of u^a (ta -> tb) to u^b (chi = 1 + ta . tb, floored)."""
    a0, a1, a2 = t[ea, 0], t[ea, 1], t[ea, 2]
    b0, b1, b2 = t[eb, 0], t[eb, 1], t[eb, 2]
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
    return math.atan2(sin_, cos_)


@leaf
def add_joint_hessian(ab, place, va, vm, vn, h, blocks):
    """Add a joint's Hessian h (6 x 6, over its edges a = x_vm - x_va, b = x_vn - x_vm)
    to the band over its three vertices: d/dx_va = -d/da, d/dx_vm = d/da - d/db,
    d/dx_vn = d/db."""
    for r in range(3):
        for c in range(3):
            haa, hab_, hba, hbb = h[r, c], h[r, c + 3], h[r + 3, c], h[r + 3, c + 3]
            blocks[0, r, c] = haa
            blocks[1, r, c] = haa - hab_ - hba + hbb
            blocks[2, r, c] = hbb
            blocks[3, r, c] = hba - haa
            blocks[4, r, c] = hba - hbb
            blocks[5, r, c] = -hba
    add_block(ab, place, va, va, blocks[0])
    add_block(ab, place, vm, vm, blocks[1])
    add_block(ab, place, vn, vn, blocks[2])
    add_block(ab, place, vm, va, blocks[3])
    add_block(ab, place, vn, vm, blocks[4])
    add_block(ab, place, vn, va, blocks[5])
