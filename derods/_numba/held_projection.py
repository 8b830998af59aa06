"""The strain limit's last resort for rods held by bodies with dofs: a projection onto
the rest lengths that moves the held points by their holders' inverse inertia and,
where it cannot converge, keeps the best shape it reached (the method:
:func:`derods.sim.held_limit.pull_holders`).

A held point p moves by W_pq r_q: W = J M^-1 J^T (3H, 3H) [1/kg] over the H held
points (J their Jacobian on the holders' dofs, M the holders' metric), r the
projection's pull on the points (the sum of grad C^T dlambda). The pulls are summed
into ``y`` (3H,), from which the holders' own step follows (dq = -M^-1 J^T y). An
edge's constraint C_j = |e^j|^2 / |ebar^j| - |ebar^j| has gradient -g_j at its first
vertex and g_j at its second (g_j = 2 e^j / |ebar^j|), so

    G_jk = sum_{p in j, q in k} s_jp s_kq g_j^T W_pq g_k     (s = -1 first, +1 second),

tridiagonal while the held points of one holder sit in neighbouring edges (the two of
a clamp, a pin); held points of one tree at both ends of a rod couple far edges, and
those entries are left out of G (the update keeps all of W: a quasi-Newton step).
Each step is taken as far as it lowers the summed squared strain (halved up to
LINE_SEARCH_HALVINGS times), for which it is a descent direction: near a taut rod,
whose uniform tension moves only its heavy holder, the full step throws the rod's bends
sideways.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .banded import cholesky_ok, solve_into
from .projection import first_order_lengths, landing_into, predict_held

#: Halvings of a projection step before the projection stops where it is.
LINE_SEARCH_HALVINGS = 30


class HeldPoints(NamedTuple):
    """The held points of :func:`limit_held`: index (n_vertices,) int64 each vertex's
    place among the H held points (-1: not held by a body with dofs); w (3H, 3H) [1/kg]
    J M^-1 J^T, how far a pull on held points moves them; y (3H,) [m/kg . kg] the
    projection's summed pull on each (written: zeroed, then added to)."""

    index: np.ndarray
    w: np.ndarray
    y: np.ndarray


@nb.njit(cache=True, inline="always")
def _wdot(g1, index, inv_mass, w, p, q, g2):
    """g1^T W_pq g2 for vertices p, q (local to the rod's arrays)."""
    ip, iq = index[p], index[q]
    if ip >= 0 and iq >= 0:
        acc = 0.0
        for a in range(3):
            for b in range(3):
                acc += g1[a] * w[3 * ip + a, 3 * iq + b] * g2[b]
        return acc
    if p == q and ip < 0:
        return inv_mass[p] * (g1[0] * g2[0] + g1[1] * g2[1] + g1[2] * g2[2])
    return 0.0


@nb.njit(cache=True, inline="always")
def _rigid(index, inv_mass, p, q):
    """Whether edge (p, q) keeps its length: both ends held by the world, or both by bodies
    with dofs (the two points of a clamp: one body)."""
    return inv_mass[p] == 0.0 and inv_mass[q] == 0.0 and (index[p] < 0) == (index[q] < 0)


@nb.njit(cache=True)
def _constraints(x, index, inv_mass, rest_len, c, gvec):
    """c (m,) <- the edges' C_j(x), gvec (m, 3) <- g_j; returns the largest |C_j| /
    |ebar^j| (|e^j|^2 / |ebar^j|^2 - 1: twice the strain, to first order; project_rod's
    measure) and the sum of their squares."""
    worst, merit = 0.0, 0.0
    for j in range(x.shape[0] - 1):
        rest = rest_len[j]
        e0, e1, e2 = x[j + 1, 0] - x[j, 0], x[j + 1, 1] - x[j, 1], x[j + 1, 2] - x[j, 2]
        c[j] = (e0 * e0 + e1 * e1 + e2 * e2) / rest - rest
        if _rigid(index, inv_mass, j, j + 1):
            c[j] = 0.0
        worst = max(worst, abs(c[j] / rest))
        merit += (c[j] / rest) ** 2
        gvec[j, 0], gvec[j, 1], gvec[j, 2] = 2.0 * e0 / rest, 2.0 * e1 / rest, 2.0 * e2 / rest
    return worst, merit


@nb.njit(cache=True)
def project_held_rod(x, inv_mass, index, w, y, rest_len, tol, max_iter):
    """Project x (n_vertices, 3) of one rod in place towards rest_len (n_edges,) [m], free
    vertex j moving by inv_mass[j] [1/kg], held point j (index[j] >= 0) by w (see the
    module docstring); the pulls on held points added to y. Returns the largest |C_j| /
    |ebar^j| left (below tol: converged); x and y are where the last step that lowered the
    summed squares left them."""
    nv = x.shape[0]
    m = nv - 1
    c = np.empty(m)
    gvec = np.empty((m, 3))
    ab = np.zeros((2, m))
    lt = np.zeros((m, 2))
    r = np.zeros((nv, 3))
    dx = np.zeros((nv, 3))
    x0 = np.empty_like(x)
    held = np.nonzero(index >= 0)[0]
    worst, merit = _constraints(x, index, inv_mass, rest_len, c, gvec)
    for _ in range(max_iter):
        if worst < tol:
            break
        for j in range(m):
            gj = gvec[j]
            ab[1, j] = 0.0
            if _rigid(index, inv_mass, j, j + 1):
                ab[0, j] = 1.0  # its multiplier is 0 (c[j] = 0) and couples to nothing
                if j > 0:
                    ab[1, j - 1] = 0.0
                continue
            ab[0, j] = (_wdot(gj, index, inv_mass, w, j + 1, j + 1, gj)
                        - 2.0 * _wdot(gj, index, inv_mass, w, j, j + 1, gj) + _wdot(gj, index, inv_mass, w, j, j, gj))
            if j < m - 1 and not _rigid(index, inv_mass, j + 1, j + 2):
                gk = gvec[j + 1]
                ab[1, j] = (_wdot(gj, index, inv_mass, w, j, j + 1, gk) - _wdot(gj, index, inv_mass, w, j, j + 2, gk)
                            - _wdot(gj, index, inv_mass, w, j + 1, j + 1, gk)
                            + _wdot(gj, index, inv_mass, w, j + 1, j + 2, gk))
        if not cholesky_ok(ab, lt):
            break
        solve_into(lt, c, 0, m)  # c <- dlambda
        r[:] = 0.0
        for j in range(m):
            for a in range(3):
                f = gvec[j, a] * c[j]
                r[j + 1, a] += f
                r[j, a] -= f
        for p in range(nv):
            for a in range(3):
                dx[p, a] = -inv_mass[p] * r[p, a] if index[p] < 0 else 0.0
        for p in held:
            for a in range(3):
                acc = 0.0
                for q in held:
                    for b in range(3):
                        acc += w[3 * index[p] + a, 3 * index[q] + b] * r[q, b]
                dx[p, a] = -acc
        x0[:] = x
        step, better = 1.0, False
        for _ in range(LINE_SEARCH_HALVINGS):
            for p in range(nv):
                for a in range(3):
                    x[p, a] = x0[p, a] + step * dx[p, a]
            new_worst, new_merit = _constraints(x, index, inv_mass, rest_len, c, gvec)
            if new_merit < merit:
                better = True
                break
            step *= 0.5
        if not better:
            x[:] = x0
            break
        worst, merit = new_worst, new_merit
        for p in held:
            for a in range(3):
                y[3 * index[p] + a] += step * r[p, a]
    return worst


@nb.njit(cache=True)
def limit_held(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, rods, limit, tol, max_iter, xp, held_x,
               points):
    """The strain limit's last resort: predict x + h (v + h a0) for the free vertices and
    held_x (n_vertices, 3) [m] for the held ones; every rod of ``rods`` (int64) whose
    predicted edge strain exceeds ``limit`` is projected towards its target lengths (below)
    (:func:`project_held_rod`, the held points moving by ``points``:
    :class:`HeldPoints`, its y zeroed and summed into) as far as it gets in max_iter
    steps, and its free dofs' a0 (n,) [m/s^2] replaced by the acceleration that lands
    there. x, xp (n_vertices, 3): positions now and (scratch) predicted. Returns (rods
    projected, the largest |C_j| / |ebar^j| left in them: below tol, converged).
    The target lengths: each edge's rest length, or the length the linearized step gave it
    (along the edge now) where that is longer, so the tension the step meant stays (the
    rods' own projection, mode 1, projects onto rest lengths)."""
    predict_held(x, place, v, a0, h, held_x, xp)
    points.y[:] = 0.0
    n_projected, left = 0, 0.0
    for i in rods:
        v0, v1 = v_off[i], v_off[i + 1]
        e0 = e_off[i]
        worst = 0.0
        for j in range(v1 - v0 - 1):
            d = xp[v0 + j + 1] - xp[v0 + j]
            worst = max(worst, abs(np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / rest_len[e0 + j] - 1.0))
        if worst <= limit:
            continue
        target = np.maximum(rest_len[e0:e0 + v1 - v0 - 1], first_order_lengths(x, xp, v0, v1 - 1))
        left = max(left, project_held_rod(xp[v0:v1], inv_mass[v0:v1], points.index[v0:v1], points.w, points.y,
                                          target, tol, max_iter))
        n_projected += 1
        landing_into(x, xp, place, v, h, v0, v1, a0)
    return n_projected, left
