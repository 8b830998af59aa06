"""The strain limit of rods held by bodies with dofs, where the holders must move with it:
held points out of the rod's reach (the holders pulled as a rope pulls what it holds,
:func:`pull_holders`), and turning edges of rods held at one end (:func:`turn_held`).

The coupled step (:mod:`derods.sim.coupled`) projects a held rod whose predicted strain
exceeds the strain limit with its held points where MuJoCo's integrator takes their
bodies. Where the step takes them apart beyond the rod's reach, no such projection
exists, and the rod kept its step (a 10 kg box swinging on a rod clamped to the world
at dt 1e-2: 62 % strain at one edge, then divergence). Here the holders give way. And
the lengthening a linearized step leaves in a turning edge, which the rods held by the
world or mocap bodies lose every step, is taken out of rods held at one end with their
holders moving too.
"""

from __future__ import annotations

import numpy as np

from .._numba.held_projection import HeldPoints, limit_held, project_held_rod
from .._numba.projection import TURNED_TOL, first_order_lengths, landing_into, predict_held
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
    vertices go this step (moved with the pull, as :func:`turn_held`, which reads it next,
    predicts them)."""
    hl, lay, r = holders, step.layout, step.rods
    lever, w, index = _held_points(holders, jac, metric, len(held_x))
    rods = hl.rods[step.limited[hl.rods] > 0]
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
        held_x[hl.held] -= (points.w @ points.y).reshape(-1, 3)
    return n + more


def _held_points(holders, jac: np.ndarray, metric: np.ndarray, n_vertices: int) -> tuple[np.ndarray, ...]:
    """How the held points move when pulled: lever (m, 3H) = M^-1 J^T (metric (m, m): the
    holders' M - h D; jac (3H, k): the held points' Jacobian), W (3H, 3H) = J M^-1 J^T
    [1/kg], and each vertex's place among the held points (n_vertices,), -1 for none."""
    lever = np.linalg.solve(metric, np.eye(len(metric))[:, holders._in_tree]) @ jac.T
    index = np.full(n_vertices, -1, dtype=np.int64)
    index[holders.held] = np.arange(len(holders.held))
    return lever, jac @ lever[holders._in_tree], index


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


def hanging_rods(layout, holders) -> np.ndarray:
    """The open rods held by bodies with dofs at one end only, the other end free (int64):
    those :func:`turn_held` projects."""
    out = []
    for rod in holders.rods:
        v0, v1 = layout.v_off[rod], layout.v_off[rod + 1]
        start, end = layout.place[v0] < 0, layout.place[v1 - 1] < 0
        if start != end:
            out.append(rod)
    return np.array(out, dtype=np.int64)


def turn_held(step, holders, rods: np.ndarray, held_x: np.ndarray, af: np.ndarray, aq: np.ndarray,
              jac: np.ndarray, metric: np.ndarray) -> int:
    """The projection of turning edges (as the rods' own strain limit's, mode 2:
    :func:`derods._numba.projection.limit_strain`) for rods held by bodies with dofs at one
    end (``rods``), with their held points moving by the holders' inverse inertia W and the
    holders' step with them (aq (m,) -= M^-1 J^T y / h^2, as :func:`pull_holders`), in steps
    without contact rows. A rod whose predicted edges are longer than their rest or
    first-order lengths (whichever is longer) by TURNED_TOL is projected onto those (onto
    its rest lengths if strained beyond the strain limit): not onto shorter first-order
    lengths, as the rods' own limit is, since a clamp's held point moves on its arc and
    leaves its first edge a first-order length of l cos(phi) (projected onto it, the edge
    was compressed 8e-4 every other step and a 0.1 kg clamping arm gained 2.4 times the
    energy its swing releases).

    The linearized step leaves an edge turned by phi 1 / cos(phi) too long and the next step
    reads that as tension, up to k_s times the strain limit (280 N on a 3 mm inextensible
    rod). Rods held by the world or by mocap bodies have their turning edges brought to
    their first-order lengths each step; held by bodies with dofs, projected with the held
    points fixed, that broke momentum (a free rod pinned to a free body: 0.42 m/s) and made
    clamping bodies gain energy. Moving the held points by W keeps the momentum exchange.
    Without it, a 1 g arm (a tenth of its rod) swinging a 0.4 m rod at dt 1e-2 stopped and
    moved on alternate steps (the spurious tension entering its lever stiffness) and gained
    0.42 (pin) and 1.08 (clamp) of the energy the swing releases. Only one-end rods and
    contact-free steps: the projection knows neither the rods' nor the holders' contacts
    (with a rod held at both ends a light free B_last was pressed into the floor), and a
    rod held at both ends has the holders' pull. af (n,), aq (m,) changed in place;
    held_x (n_vertices, 3) [m] moved with the held points. Returns how many rods were
    projected."""
    hl, lay, r, h = holders, step.layout, step.rods, step.h
    lever, w, index = _held_points(holders, jac, metric, len(held_x))
    w = 0.5 * (w + w.T)
    x = step.x_start
    xp = np.empty_like(x)
    predict_held(x, lay.place, step.v, af, h, held_x, xp)
    y, pull = np.zeros(3 * len(hl.held)), np.zeros(3 * len(hl.held))
    n = 0
    for rod in rods:
        if step.limited[rod] == 0:
            continue
        v0, v1, e0 = r.v_off[rod], r.v_off[rod + 1], r.e_off[rod]
        rest = r.rest_len[e0:e0 + v1 - v0 - 1]
        length = np.linalg.norm(np.diff(xp[v0:v1], axis=0), axis=1)
        first = first_order_lengths(x, xp, v0, v1 - 1)
        longer = np.maximum(first, rest)
        if np.max(np.abs(length / rest - 1.0)) > step.strain_limit or np.max(np.abs(first / rest - 1.0)) > \
                step.strain_limit:
            target = rest.copy()
        elif np.max((length - longer) / rest) > TURNED_TOL:
            target = longer
        else:
            continue
        shape = xp[v0:v1].copy()
        pull[:] = 0.0
        if project_held_rod(shape, step.inv_mass[v0:v1], index[v0:v1], w, pull, target, PROJECTION_TOL,
                            PROJECTION_MAX_ITER) > PROJECTION_TOL:
            continue  # no shape: the rod keeps its step
        y += pull
        xp[v0:v1] = shape
        landing_into(x, xp, lay.place, step.v, h, v0, v1, af)
        n += 1
    if n:
        aq -= lever @ y / (h * h)
        held_x[hl.held] -= (w @ y).reshape(-1, 3)
    return n
