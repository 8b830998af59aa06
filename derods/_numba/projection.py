"""Fast projection of open rods onto their rest edge lengths (Goldenthal et al. 2007,
Algorithm 1; the method: :mod:`derods.sim.projection`), compiled: one rod or all of a
world's in one call."""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import cholesky_into, solve_into


#: Turning edges: the relative lengthening [-] beyond which a predicted edge is brought
#: back to the length the linearized step gave it (see :func:`limit_strain`): 1e-9 is an
#: edge turning 4.5e-5 rad in a step; what is left acts as a tension of k_s 1e-9 (3e-4 N
#: for an inextensible 3 mm rod).
TURNED_TOL = 1e-9


@nb.njit(cache=True)
def project_rod(x, inv_mass, rest_len, tol, max_iter):
    """Project x (n_vertices, 3) in place, moving vertex j by inv_mass[j] (0: held);
    returns the iterations used, or -1 (with the last strain left in x's distance from
    the manifold) if it did not converge. Edges between two held vertices keep their
    length."""
    nv = x.shape[0]
    lo, hi = -1, -1
    for j in range(nv - 1):
        if inv_mass[j] + inv_mass[j + 1] > 0:
            if lo < 0:
                lo = j
            hi = j + 1
    if lo < 0:
        return 0
    m = hi - lo
    c = np.empty(m)
    gvec = np.empty((m, 3))
    ab = np.zeros((2, m))
    lt = np.zeros((m, 2))
    for it in range(max_iter + 1):
        worst = 0.0
        for j in range(m):
            e0 = x[lo + j + 1, 0] - x[lo + j, 0]
            e1 = x[lo + j + 1, 1] - x[lo + j, 1]
            e2 = x[lo + j + 1, 2] - x[lo + j, 2]
            rest = rest_len[lo + j]
            c[j] = (e0 * e0 + e1 * e1 + e2 * e2) / rest - rest
            if inv_mass[lo + j] + inv_mass[lo + j + 1] == 0.0:
                c[j] = 0.0  # between two held vertices: nothing to move, left as it is
            worst = max(worst, abs(c[j] / rest))
            gvec[j, 0], gvec[j, 1], gvec[j, 2] = 2.0 * e0 / rest, 2.0 * e1 / rest, 2.0 * e2 / rest
        if worst < tol:
            return it
        if it == max_iter:
            break
        for j in range(m):
            w0, w1 = inv_mass[lo + j], inv_mass[lo + j + 1]
            ab[0, j] = (gvec[j, 0] ** 2 + gvec[j, 1] ** 2 + gvec[j, 2] ** 2) * (w0 + w1)
            if w0 + w1 == 0.0:
                ab[0, j] = 1.0  # its multiplier is 0 (c[j] = 0) and couples to nothing
            if j < m - 1:
                ab[1, j] = -(gvec[j, 0] * gvec[j + 1, 0] + gvec[j, 1] * gvec[j + 1, 1]
                             + gvec[j, 2] * gvec[j + 1, 2]) * w1
            else:
                ab[1, j] = 0.0
        cholesky_into(ab, lt)
        solve_into(lt, c, 0, m)  # c <- dlambda
        for j in range(m):
            for a in range(3):
                f = gvec[j, a] * c[j]
                x[lo + j + 1, a] -= inv_mass[lo + j + 1] * f
                x[lo + j, a] += inv_mass[lo + j] * f
    return -1


@nb.njit(cache=True)
def predict_into(x, place, v, a0, h, xp):
    """xp (n_vertices, 3) <- x + h (v + h a0) for the free vertices (place >= 0), x elsewhere."""
    xp[:] = x
    for vtx in range(x.shape[0]):
        p = place[vtx]
        if p >= 0:
            for a in range(3):
                k = 3 * p + a
                xp[vtx, a] += h * (v[k] + h * a0[k])


@nb.njit(cache=True)
def landing_into(x, xp, place, v, h, lo, hi, accel):
    """accel (n,) [m/s^2] of the free dofs of vertices lo..hi-1 that take them from x with
    velocity v to xp in one step h."""
    for vtx in range(lo, hi):
        p = place[vtx]
        if p >= 0:
            for a in range(3):
                k = 3 * p + a
                accel[k] = ((xp[vtx, a] - x[vtx, a]) / h - v[k]) / h


@nb.njit(cache=True)
def projection_step(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, tol, max_iter, xp, accel):
    """The projection mode's acceleration [m/s^2] (n,) of every free dof: predict
    x + h (v + h a0) for the free vertices, project each rod, and take the acceleration
    that lands there. x, xp (n_vertices, 3): positions now and (scratch) projected.
    Returns the first rod that did not converge, or -1."""
    predict_into(x, place, v, a0, h, xp)
    for i in range(len(v_off) - 1):
        v0, v1 = v_off[i], v_off[i + 1]
        if project_rod(xp[v0:v1], inv_mass[v0:v1], rest_len[e_off[i]:e_off[i + 1]], tol, max_iter) < 0:
            return i
    landing_into(x, xp, place, v, h, 0, x.shape[0], accel)
    return -1


@nb.njit(cache=True)
def limit_strain(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, limited, limit, tol, max_iter, xp, held_x):
    """Strain limiting of the implicit step: predict x + h (v + h a0) for the free
    vertices and held_x (n_vertices, 3) for the held ones (where their bodies take them;
    x for the world's); every rod flagged in ``limited`` (n_rods,) whose predicted edge strain
    exceeds ``limit`` is projected onto its rest lengths rest_len (n_edges,) [m] (to
    ``tol``), and for rods flagged 2 every other one whose edges the step turned onto the
    lengths the linearized step gave them (onto the rest lengths if those are strained
    beyond ``limit``), and its free dofs' a0 (n,) [m/s^2] replaced by the acceleration
    that lands there.

    An edge turned by phi in a linearized step comes out 1 / cos(phi) longer than the
    step meant (its length along the edge now, t . (predicted edge)); read at the next
    step as tension, k_s phi^2 / 2, that lengthening held turning edges still (an
    inextensible rod rotating freely at 1 rad/s, dt 1e-2: 0.117 rad of 0.5 in 0.5 s). So
    the edges are brought to their first-order lengths, once any edge of the rod is
    TURNED_TOL longer than that; the tension the step meant stays.

    A rod the projection cannot bring there in ``max_iter`` iterations (held taut between
    pins: no point of the constraint set is near) keeps its a0: the limit is a best
    effort, not a constraint. x, xp (n_vertices, 3): positions now and (scratch)
    predicted. Returns (rods projected, rods left as they were)."""
    predict_held(x, place, v, a0, h, held_x, xp)
    return limit_rods(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, limited, limit, tol, max_iter, xp, 0,
                      len(v_off) - 1)


@nb.njit(cache=True, nogil=True)
def limit_chunk(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, limited, limit, tol, max_iter, xp, held_x,
                chunk):
    """:func:`limit_strain` for the rods chunk[0] .. chunk[1] - 1 (``chunk`` (2,), a chunk of a
    :class:`derods._numba.parallel.Split`), predicting their vertices only; the call releases
    the GIL, so that the chunks of a world run at once on threads."""
    lo, hi = v_off[chunk[0]], v_off[chunk[1]]
    predict_held(x[lo:hi], place[lo:hi], v, a0, h, held_x[lo:hi], xp[lo:hi])
    return limit_rods(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, limited, limit, tol, max_iter, xp,
                      chunk[0], chunk[1])


@nb.njit(cache=True)
def predict_held(x, place, v, a0, h, held_x, xp):
    """xp (n_vertices, 3) <- x + h (v + h a0) for the free vertices, held_x for the held ones."""
    predict_into(x, place, v, a0, h, xp)
    for vtx in range(x.shape[0]):
        if place[vtx] < 0:
            for a in range(3):
                xp[vtx, a] = held_x[vtx, a]


# Inlined into both callers, as derods._numba.step.rods_range.
@nb.njit(cache=True, inline="always")
def limit_rods(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, limited, limit, tol, max_iter, xp, r0, r1):
    """:func:`limit_strain` for rods r0 .. r1 - 1, their vertices predicted in xp: (rods
    projected, rods left as they were)."""
    n_projected, n_left = 0, 0
    for i in range(r0, r1):
        if limited[i] == 0:
            continue
        v0, v1 = v_off[i], v_off[i + 1]
        e0, ne = e_off[i], v1 - v0 - 1
        target = np.empty(ne)
        worst, turned, first = 0.0, 0.0, 0.0
        for j in range(ne):
            d0 = xp[v0 + j + 1, 0] - xp[v0 + j, 0]
            d1 = xp[v0 + j + 1, 1] - xp[v0 + j, 1]
            d2 = xp[v0 + j + 1, 2] - xp[v0 + j, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            worst = max(worst, abs(length / rest_len[e0 + j] - 1.0))
            target[j] = first_order_length(x, xp, v0 + j)
            turned = max(turned, (length - target[j]) / rest_len[e0 + j])
            first = max(first, abs(target[j] / rest_len[e0 + j] - 1.0))
        if worst > limit or (limited[i] == 2 and first > limit):
            target[:] = rest_len[e0:e0 + ne]
        elif limited[i] == 1 or not turned > TURNED_TOL:
            continue
        if project_rod(xp[v0:v1], inv_mass[v0:v1], target, tol, max_iter) < 0:
            n_left += 1
            continue
        n_projected += 1
        landing_into(x, xp, place, v, h, v0, v1, a0)
    return n_projected, n_left


@nb.njit(cache=True, inline="always")
def first_order_length(x, xp, j):
    """The length [m] the linearized step gave edge (j, j + 1): its predicted edge (xp
    (n_vertices, 3)) along the edge now (x)."""
    c0, c1, c2 = x[j + 1, 0] - x[j, 0], x[j + 1, 1] - x[j, 1], x[j + 1, 2] - x[j, 2]
    d0, d1, d2 = xp[j + 1, 0] - xp[j, 0], xp[j + 1, 1] - xp[j, 1], xp[j + 1, 2] - xp[j, 2]
    return (c0 * d0 + c1 * d1 + c2 * d2) / np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)


@nb.njit(cache=True)
def first_order_lengths(x, xp, lo, hi):
    """:func:`first_order_length` of edges lo .. hi - 1, shape (hi - lo,) [m]."""
    out = np.empty(hi - lo)
    for j in range(lo, hi):
        out[j - lo] = first_order_length(x, xp, j)
    return out


@nb.njit(cache=True)
def touching_into(force, inv_mass, free_vertex, weight, out):
    """out (n_vertices,) <- inv_mass with the free vertices a contact pushes on (force (n,)
    [N] on their dofs not zero; free_vertex (n / 3,): each free place's vertex) made
    ``weight`` times lighter."""
    out[:] = inv_mass
    for p in range(len(free_vertex)):
        if force[3 * p] != 0.0 or force[3 * p + 1] != 0.0 or force[3 * p + 2] != 0.0:
            out[free_vertex[p]] *= weight
