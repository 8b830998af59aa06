"""Compiled mirror of :mod:`derods.step`: one step's terms for a set of rods of any
sizes, in one call.

For every rod: transport the reference frames in time, turn the frames of
clamps held by moving bodies, solve the quasistatic twist, and evaluate the
gradient and the positive semi-definite banded Hessian. An isotropic, naturally
straight rod (:func:`isotropic_joints`) has its twist in closed form and carries
it as a reduced term (stretch + isotropic bending + a rank-one twist term);
an anisotropic or naturally curved rod (:func:`derods._numba.material.material_rod`)
needs Newton's method on its twist angles. At a few hundred vertices a numpy call costs
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

import numba as nb
import numpy as np

from .material import material_rod
from .rod_geometry import Scratch, add_joint_hessian, curvature_binormal, edges, joint_stencil, reference_twist
from .rod_geometry import turn_clamps, turning_angle


@nb.njit(cache=True)
def isotropic_joints(rods, i, t, u, theta, theta_first, theta_last, place, grad, ab, g_tw, work):
    """Bending and the closed-form twist of rod i of ``rods`` (:class:`derods.step.RodSet`),
    isotropic and naturally straight, after :func:`derods._numba.rod_geometry.edges`: t, u,
    theta, place, grad, g_tw are the rod's slices, theta_first, theta_last [rad] its held
    end angles this step, ab its band, work a :class:`derods._numba.rod_geometry.Scratch`
    (edge_len filled by edges). Adds to grad [N] and the band [N/m]; writes g_tw [1/m]
    (d total reference twist / dx) and theta [rad]. The rod bends by its measure (Bergou's kb,
    or the turning angle's where rods.turning_angle[i]); its twist by Bergou's kb, the holonomy
    of transport, either way. Returns (energy [J], twisting moment lam [N m], twist
    stiffness c [N m])."""
    j0, j1 = rods.j_off[i], rods.j_off[i + 1]
    vlen, mbar = rods.vlen[j0:j1], rods.mbar[j0:j1]
    alpha, beta, closed, has_twist = rods.alpha[i], rods.beta[i], rods.closed[i], rods.has_twist[i]
    angle = rods.turning_angle[i]
    clamped, anchor_last, total_twist = rods.clamped[i], rods.anchor_last[i], rods.total_twist[i]
    le, ref, ja, jb, h6, blocks = work.edge_len, work.ref_twist, work.jac_a, work.jac_b, work.h6, work.blocks
    nv = grad.shape[0]
    ne = nv if closed else nv - 1
    nj = nv if closed else nv - 2
    energy = 0.0
    for p in range(nv):
        for a in range(3):
            g_tw[p, a] = 0.0
    for k in range(nj):
        ea, eb, va, vm, vn = joint_stencil(k, closed, ne, nv)
        kb0, kb1, kb2, chi = curvature_binormal(t, le, ea, eb, ja, jb)
        # bk: the curvature the rod bends by (ja, jb become its Jacobians); kb stays for the twist.
        bk0, bk1, bk2 = turning_angle(kb0, kb1, kb2, ja, jb) if angle else (kb0, kb1, kb2)
        cb = alpha / vlen[k]
        energy += cb * (bk0 * bk0 + bk1 * bk1 + bk2 * bk2)
        two_c = 2.0 * cb
        for c in range(3):
            ga = two_c * (ja[0, c] * bk0 + ja[1, c] * bk1 + ja[2, c] * bk2)
            gb = two_c * (jb[0, c] * bk0 + jb[1, c] * bk1 + jb[2, c] * bk2)
            grad[va, c] -= ga
            grad[vm, c] += ga - gb
            grad[vn, c] += gb
        # Gauss-Newton Hessian 2c J^T J over (a, b), mapped to the three vertices.
        for r in range(3):
            for c in range(3):
                h6[r, c] = two_c * (ja[0, r] * ja[0, c] + ja[1, r] * ja[1, c] + ja[2, r] * ja[2, c])
                h6[r, c + 3] = two_c * (ja[0, r] * jb[0, c] + ja[1, r] * jb[1, c] + ja[2, r] * jb[2, c])
                h6[r + 3, c] = two_c * (jb[0, r] * ja[0, c] + jb[1, r] * ja[1, c] + jb[2, r] * ja[2, c])
                h6[r + 3, c + 3] = two_c * (jb[0, r] * jb[0, c] + jb[1, r] * jb[1, c] + jb[2, r] * jb[2, c])
        add_joint_hessian(ab, place, va, vm, vn, h6, blocks)
        if not has_twist:
            continue
        ref[k] = reference_twist(u, t, ea, eb, chi)
        ia, ib = 0.5 / le[ea], 0.5 / le[eb]
        kbv = (kb0, kb1, kb2)
        for c in range(3):
            g_tw[va, c] -= kbv[c] * ia
            g_tw[vm, c] += kbv[c] * (ia - ib)
            g_tw[vn, c] += kbv[c] * ib
    lam = 0.0
    coef = 0.0
    if not has_twist:
        return energy, lam, coef
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
        for p in range(nv):
            for a in range(3):
                grad[p, a] += lam * g_tw[p, a]
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
def rods_step(rods, ends, frames, x, xmat, place, bands, band_of_rod, out):
    """Every rod of a set, laid end to end: rods (:class:`derods.step.RodSet`), their clamps
    on moving bodies ends (:class:`derods.step.EndBodies`), their state frames
    (:class:`derods.step.Frames`: u, t, theta (n_edges, ...) transported and solved in
    place; theta_end (n_rods, 2) [rad], the unwrapped angles of clamps on moving bodies,
    updated). In: positions x (n_vertices, 3) [m]; xmat (n_bodies, 9), MuJoCo's body
    orientations. Out (:class:`derods.step.Terms`): grad (n_vertices, 3) [N]; bands
    (n_bands, rows, n_dofs), lower bands of the PSD Hessian [N/m], zeroed here first: rod
    i adds to bands[band_of_rod[i]] at its vertices' places ``place`` (n_vertices,) (one
    band for all rods in a world; one per rod for :meth:`derods.Rod.step_terms`); g_tw
    (n_vertices, 3) [1/m], the reduced twist term's direction (zero for a rod of kind 2);
    energy, lam, coef, strain per rod; end_moment (n_rods, 2) [N m], dE/dtheta of each
    rod's first and last edge. kind: 1 isotropic and naturally straight, 2 anisotropic or
    naturally curved (Newton twist solve). Returns the first rod whose largest |strain| is
    not finite or exceeds ``out.strain`` on entry, else -1 (out.strain (n_rods,): limit
    in, value out)."""
    bands[:] = 0.0
    return rods_range(rods, ends, frames, x, xmat, place, bands, band_of_rod, out, 0, len(rods.v_off) - 1)


@nb.njit(cache=True, nogil=True)
def rods_chunk(rods, ends, frames, x, xmat, place, bands, band_of_rod, out, chunk):
    """:func:`rods_step` for the rods chunk[0] .. chunk[1] - 1 (``chunk`` (2,), a chunk of a
    :class:`derods._numba.parallel.Split`): each of them zeroes its own places' columns of
    its band, not the whole band, and writes only its own slices and columns; the call
    releases the GIL, so that the chunks of a world run at once on threads. Returns the
    first of them strained beyond ``out.strain`` (or not finite), else -1."""
    v_off = rods.v_off
    for i in range(chunk[0], chunk[1]):
        ab = bands[band_of_rod[i]]
        for vtx in range(v_off[i], v_off[i + 1]):
            p = place[vtx]
            if p >= 0:
                ab[:, 3 * p:3 * p + 3] = 0.0
    return rods_range(rods, ends, frames, x, xmat, place, bands, band_of_rod, out, chunk[0], chunk[1])


# Inlined into both callers: called as a function, the whole-world step of a 20-edge
# cantilever took 0.4 us more.
@nb.njit(cache=True, inline="always")
def rods_range(rods, ends, frames, x, xmat, place, bands, band_of_rod, out, r0, r1):
    """:func:`rods_step` for rods r0 .. r1 - 1, their bands' columns zeroed: the first of
    them strained beyond ``out.strain`` (or not finite), else -1."""
    # The bundles' fields read once: a field read in the loop costs a reference count per rod.
    v_off, e_off, rest_len, ks, kind, closed = rods.v_off, rods.e_off, rods.rest_len, rods.ks, rods.kind, rods.closed
    clamped, theta_first, theta_last = rods.clamped, rods.theta_first, rods.theta_last
    u, t, theta, theta_end = frames.u, frames.t, frames.theta, frames.theta_end
    clamp_body, clamp_dir = ends.body, ends.director
    grad, g_tw, strain, energy, lam, coef, end_moment = out.grad, out.g_tw, out.strain, out.energy, out.lam, out.coef, \
        out.end_moment
    max_nv = 0
    for i in range(r0, r1):
        max_nv = max(max_nv, v_off[i + 1] - v_off[i])
    work = Scratch(np.empty(max_nv), np.empty(max_nv), np.empty((max_nv, 3)), np.empty((3, 3)), np.empty((3, 3)),
                   np.empty((6, 6)), np.empty((6, 3, 3)))
    edge_len, blocks = work.edge_len, work.blocks
    first_bad = -1
    for i in range(r0, r1):
        v0, v1 = v_off[i], v_off[i + 1]
        e0, e1 = e_off[i], e_off[i + 1]
        ab = bands[band_of_rod[i]]
        xi, ui, ti, thi = x[v0:v1], u[e0:e1], t[e0:e1], theta[e0:e1]
        e_s, st = edges(xi, ui, ti, rest_len[e0:e1], ks[i], closed[i], place[v0:v1], grad[v0:v1], ab, edge_len,
                        blocks)
        th_first, th_last = turn_clamps(ui, ti, e1 - e0, clamp_body[i], clamp_dir[i], theta_end[i], xmat,
                                        theta_first[i], theta_last[i])
        if kind[i] == 1:
            e_b, lm, cf = isotropic_joints(rods, i, ti, ui, thi, th_first, th_last, place[v0:v1], grad[v0:v1], ab,
                                           g_tw[v0:v1], work)
            held = clamped[i] and not closed[i]
            end_moment[i, 0] = -lm if held else 0.0
            end_moment[i, 1] = lm if held else 0.0
        else:
            g_tw[v0:v1] = 0.0
            e_b, m_first, m_last = material_rod(rods, i, ti, ui, thi, th_first, th_last, place[v0:v1], grad[v0:v1],
                                                ab, work)
            lm, cf = 0.0, 0.0
            end_moment[i, 0] = m_first
            end_moment[i, 1] = m_last
        energy[i] = e_s + e_b
        lam[i] = lm
        coef[i] = cf
        if first_bad < 0 and not st <= strain[i]:
            first_bad = i
        strain[i] = st
    return first_bad
