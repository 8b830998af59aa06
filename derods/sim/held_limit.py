"""The strain limit of rods held by bodies with dofs where the held points are out of
reach: the holders pulled as a rope pulls what it holds.

The coupled step (:mod:`derods.sim.coupled`) projects a held rod whose predicted strain
exceeds the strain limit with its held points where MuJoCo's integrator takes their
bodies. Where the step takes them apart beyond the rod's reach, no such projection
exists, and the rod kept its step (a 10 kg box swinging on a rod clamped to the world
at dt 1e-2: 62 % strain at one edge, then divergence). Here the holders give way.
"""

from __future__ import annotations

import numpy as np

from .._numba.held_projection import HeldPoints, limit_held
from .._numba.projection import first_order_lengths, predict_held
from .projection import PROJECTION_MAX_ITER, PROJECTION_TOL


def pull_holders(step, holders, held_x: np.ndarray, af: np.ndarray, aq: np.ndarray, jac: np.ndarray,
                 metric: np.ndarray) -> int:
    """The strain limit again for the rods it could not project with their held points
    where the coupled solve takes them (a 10 kg box swinging on a 0.4 m rod clamped to
    the world snaps it taut; the linear step moves the box along its arc's tangent, at
    dt 1e-2 7 mm beyond the rod's reach, and the rod, left with its step, came out 62 %
    strained at one edge and diverged). As a rope pulls what it holds, the holders move
    here too, by their inverse inertia W = J M^-1 J^T (metric (m, m): M - h D), and
    their step with them: aq (m,) [m/s^2 or rad/s^2] -= M^-1 J^T y / h^2, y (3H,) the
    pull on the held points (a momentum exchange, as between the rods' own vertices).

    First a rod's two held ends out of its reach are pulled within it (:func:`_pull_taut`)
    and the rod projected as before; then every rod still strained beyond the limit is
    projected with its held points moving by W, as far as a damped projection gets
    (:func:`derods._numba.held_projection.limit_held`; the full Newton step of the
    projection with W crept: the rod nearly straight and 28000 times lighter than its
    box, 50 steps moved the box 9 um of the 0.15 mm needed). Returns how many rods were
    projected; af (n,) changed for them. held_x (n_vertices, 3) [m]: where the held
    vertices go this step (moved with the pull)."""
    hl, lay, r = holders, step.layout, step.rods
    lever = np.linalg.solve(metric, np.eye(len(metric))[:, hl._in_tree]) @ jac.T  # M^-1 J^T, (m, 3H)
    w = jac @ lever[hl._in_tree]
    index = np.full(len(held_x), -1, dtype=np.int64)  # each vertex's place among the held points
    index[hl.held] = np.arange(len(hl.held))
    rods = np.unique(hl.rod_of_held)
    rods = rods[step.limited[rods] > 0]
    pulled = _pull_taut(step, hl, rods, held_x, index, af, aq, lever, w)
    n = 0
    if pulled.any():
        n = step._limit_kernel(step.x_start, r.v_off, r.e_off, r.rest_len, step.inv_mass, lay.place, step.v, af,
                               step.h, pulled, step.strain_limit, PROJECTION_TOL, PROJECTION_MAX_ITER, step._xp,
                               held_x)[0]
    points = HeldPoints(index, 0.5 * (w + w.T), np.zeros(3 * len(hl.held)))
    more, _ = limit_held(step.x_start, r.v_off, r.e_off, r.rest_len, step.inv_mass, lay.place, step.v, af, step.h,
                         rods, step.strain_limit, PROJECTION_TOL, PROJECTION_MAX_ITER, step._xp, held_x, points)
    if more:
        aq -= lever @ points.y / (step.h * step.h)
    return n + more


def _pull_taut(step, holders, rods: np.ndarray, held_x: np.ndarray, index: np.ndarray, af: np.ndarray,
               aq: np.ndarray, lever: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Pull the held points at the two ends of each rod of ``rods`` (at least one on a body
    with dofs) that the step takes apart beyond the rod's reach (the sum of its edges' rest
    or first-order lengths, whichever is longer: the tension the step meant stays) back to
    it, along the line between them, moving held_x and aq (see :func:`pull_holders`;
    index (n_vertices,): each vertex's place among the held points, -1 for none; lever
    (m, 3H): M^-1 J^T, w (3H, 3H): W). Returns the rods pulled, as the projection's
    ``limited`` flags (n_rods,)."""
    hl, lay, r, x = holders, step.layout, step.rods, step.x_start
    pulled = np.zeros_like(step.limited)
    xp = np.empty_like(x)
    predict_held(x, lay.place, step.v, af, step.h, held_x, xp)
    for rod in rods:
        v0, v1 = r.v_off[rod], r.v_off[rod + 1]
        free = np.flatnonzero(lay.place[v0:v1] >= 0)
        if not len(free) or free[0] == 0 or free[-1] == v1 - v0 - 1:
            continue  # an end not held: nothing to pull against
        a, b = v0 + free[0] - 1, v0 + free[-1] + 1  # the innermost held vertex at either end
        if index[a] < 0 and index[b] < 0:
            continue  # both held by the world or mocap bodies: nothing moves
        e0 = r.e_off[rod] + a - v0
        reach = float(np.sum(np.maximum(first_order_lengths(x, xp, a, b), r.rest_len[e0:e0 + b - a])))
        d = held_x[b] - held_x[a]
        dist = float(np.linalg.norm(d))
        if dist <= reach:
            continue
        line = d / dist
        y = np.zeros(3 * len(hl.held))  # a unit pull drawing b towards a
        for vtx, sign in ((a, -1.0), (b, 1.0)):
            if index[vtx] >= 0:
                y[3 * index[vtx]:3 * index[vtx] + 3] += sign * line
        moved = -(w @ y).reshape(-1, 3)  # the held points' motion per unit pull [m / (kg m / s^2 . s^2)]
        closing = float(line @ ((moved[index[b]] if index[b] >= 0 else 0.0)
                                - (moved[index[a]] if index[a] >= 0 else 0.0)))
        if closing >= 0.0:
            continue
        excess = dist - reach
        pull = -excess / closing
        held_x[hl.held] += pull * moved
        aq -= lever @ (pull * y) / (step.h * step.h)
        pulled[rod] = 1
    return pulled
