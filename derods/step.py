"""One step's terms for a set of rods: transport, twist, forces and the PSD band, in one call.

What an implicit step needs from every rod of a world, computed once per step:
the reference frames transported in time to the new tangents (Bergou et al.
2010, 3.1), the frames of clamps held by moving bodies, the quasistatic twist
(Bergou et al. 2008, 4.4), the gradient of stretch + bending + twist, and the
positive semi-definite Hessian as one lower band over the dofs in their solve
order. Rods of any sizes are laid end to end in flat arrays (:class:`RodSet`,
frozen; :class:`Frames`, the state), so one compiled call
(:func:`derods._numba.step.rods_step`) serves them all, and Python's work per
step does not grow with the number of rods. The bundles are named tuples, which the
compiled step takes as they are: the frozen :class:`RodSet` and :class:`EndBodies`, the
state :class:`Frames` and the outputs :class:`Terms` (their arrays are changed in place).

The compiled path covers every rod: isotropic, naturally straight ones with the
twist in closed form, anisotropic or naturally curved ones with Newton's method
on their twist angles. Its oracle is the numpy path of
:meth:`derods.rod.Rod.step_terms` (``use_kernel=False``), held to it by
tests/test_step.py.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from .twist import TwistBoundary


class RodSet(NamedTuple):
    """Rods laid end to end: per-rod constants and offsets into flat per-vertex,
    per-edge and per-joint arrays (rod i owns vertices v_off[i]:v_off[i + 1], etc.).

    v_off, e_off, j_off: offsets, shape (n_rods + 1,), int64.
    rest_len: rest edge lengths [m], shape (n_edges,). vlen: vertex lengths l_k [m],
    shape (n_joints,). mbar: natural twist per joint [rad], shape (n_joints,). wbar: rest
    material curvatures omegabar per joint and side, shape (n_joints, 2, 2) (zero for a
    naturally straight rod). edge_pos: each edge's place in the rod's twist system
    (identity; a ring's zig-zag order, :func:`derods.stencil.ring_order`), shape (n_edges,).
    ks [N], alpha (isotropic bending) [N m^2], beta [N m^2]: stiffnesses, shape (n_rods,);
    bend: principal bending stiffnesses (B1, B2) [N m^2], shape (n_rods, 2). turning_angle:
    True for a rod that bends by the turning angle (``Rod(bending="angle")``,
    :class:`derods.geometry.TurningAngle`), False for Bergou's kb, shape (n_rods,), bool.
    kind: 1 for an isotropic, naturally straight rod (twist in closed form, a reduced
    rank-one term), 2 for an anisotropic or naturally curved one (Newton on the twist
    angles), shape (n_rods,). closed, has_twist (the rod carries the twist term), clamped
    (both ends' frames held, or a ring's total twist imposed), anchor_last (only the last
    edge's frame held), fix_first, fix_last (that end's frame held): shape (n_rods,),
    bool. theta_first, theta_last [rad]: held angles of the end edges (0 where not held);
    total_twist [rad]: a ring's imposed twist; shape (n_rods,).
    """

    v_off: np.ndarray
    e_off: np.ndarray
    j_off: np.ndarray
    rest_len: np.ndarray
    vlen: np.ndarray
    mbar: np.ndarray
    wbar: np.ndarray
    edge_pos: np.ndarray
    ks: np.ndarray
    alpha: np.ndarray
    bend: np.ndarray
    turning_angle: np.ndarray
    beta: np.ndarray
    kind: np.ndarray
    closed: np.ndarray
    has_twist: np.ndarray
    clamped: np.ndarray
    anchor_last: np.ndarray
    fix_first: np.ndarray
    fix_last: np.ndarray
    theta_first: np.ndarray
    theta_last: np.ndarray
    total_twist: np.ndarray

    @classmethod
    def of(cls, rods: Sequence, boundaries: Sequence[TwistBoundary | None] | None = None) -> "RodSet":
        """The set of ``rods`` (:class:`derods.Rod`, each one rod or a batch of equal
        rods, expanded in order); boundaries: per rod, a boundary replacing its own."""
        from .stencil import ring_order

        if boundaries is None:
            boundaries = [None] * len(rods)
        counts = {"v": [], "e": [], "j": []}
        cols = {k: [] for k in ("rest_len", "vlen", "mbar", "wbar", "edge_pos")}
        per_rod = {k: [] for k in ("ks", "alpha", "bend", "turning_angle", "beta", "kind", "closed", "has_twist",
                                   "clamped", "anchor_last", "fix_first", "fix_last", "theta_first", "theta_last",
                                   "total_twist")}
        for rod, bd in zip(rods, boundaries):
            bd = rod.boundary if bd is None else bd
            lead = rod.rest_x.shape[:-2]
            batch = int(np.prod(lead, dtype=int))
            ne, nj = rod.n_edges, rod.vlen.shape[-1]
            rest_len = np.broadcast_to(rod.rest_len, lead + (ne,)).reshape(batch, ne)
            vlen = np.broadcast_to(rod.vlen, lead + (nj,)).reshape(batch, nj)
            mbar = np.broadcast_to(rod.mbar, lead + (nj,)).reshape(batch, nj)
            wbar = (np.zeros((batch, nj, 2, 2)) if rod.rest_curvature is None
                    else np.broadcast_to(rod.rest_curvature, lead + (nj, 2, 2)).reshape(batch, nj, 2, 2))
            edge_pos = np.argsort(ring_order(ne)) if rod.closed else np.arange(ne)
            fix_first = not rod.closed and (bd.kind == "clamped" or bd.theta_first is not None)
            fix_last = not rod.closed and (bd.kind == "clamped" or bd.theta_last is not None)
            for b in range(batch):
                counts["v"].append(rod.n_vertices)
                counts["e"].append(ne)
                counts["j"].append(nj)
                for key, val in (("rest_len", rest_len[b]), ("vlen", vlen[b]), ("mbar", mbar[b]), ("wbar", wbar[b]),
                                 ("edge_pos", edge_pos)):
                    cols[key].append(val)
                for key, val in (("ks", rod.ks), ("alpha", rod.material.alpha), ("bend", rod.material.bend_stiffness),
                                 ("turning_angle", rod.bending == "angle"),
                                 ("beta", rod.material.beta), ("kind", 1 if rod.has_closed_form_twist else 2),
                                 ("closed", rod.closed), ("has_twist", "twist" in rod.active_terms),
                                 ("clamped", bd.kind in ("clamped", "ring")),
                                 ("anchor_last", not rod.closed and bd.kind == "free" and bd.theta_first is None
                                  and bd.theta_last is not None),
                                 ("fix_first", fix_first), ("fix_last", fix_last),
                                 ("theta_first", bd.theta_first or 0.0), ("theta_last", bd.theta_last or 0.0),
                                 ("total_twist", bd.total_twist)):
                    per_rod[key].append(val)
        off = lambda c: np.concatenate([[0], np.cumsum(c)]).astype(np.int64)  # noqa: E731
        flat = {k: np.ascontiguousarray(np.concatenate(v), dtype=np.int64 if k == "edge_pos" else float)
                for k, v in cols.items()}
        types = {"kind": np.int64, "turning_angle": bool, "closed": bool, "has_twist": bool, "clamped": bool,
                 "anchor_last": bool, "fix_first": bool, "fix_last": bool}
        rod_arrays = {k: np.array(v, dtype=types.get(k, float)) for k, v in per_rod.items()}
        return cls(off(counts["v"]), off(counts["e"]), off(counts["j"]), **flat, **rod_arrays)

    @property
    def n_rods(self) -> int:
        return len(self.v_off) - 1

    @property
    def n_vertices(self) -> int:
        return int(self.v_off[-1])

    @property
    def n_edges(self) -> int:
        return int(self.e_off[-1])


class Frames(NamedTuple):
    """What the step carries from one step to the next, for every rod of a set.

    u: reference directors, shape (n_edges, 3). t: unit tangents they were last
    transported to, shape (n_edges, 3). theta: twist angles [rad], shape (n_edges,).
    theta_end: unwrapped angles [rad] of clamps held by moving bodies, shape (n_rods, 2)
    (start, end; unused where an end is not so held).
    """

    u: np.ndarray
    t: np.ndarray
    theta: np.ndarray
    theta_end: np.ndarray

    @classmethod
    def of(cls, states: Sequence) -> "Frames":
        """Frames from per-rod :class:`derods.RodState` (each one rod or a batch)."""
        u = np.concatenate([np.reshape(s.u, (-1, 3)) for s in states])
        t = np.concatenate([np.reshape(s.t, (-1, 3)) for s in states])
        theta = np.concatenate([np.reshape(s.theta, -1) for s in states]).astype(float)
        n_rods = sum(int(np.prod(np.shape(s.theta)[:-1], dtype=int)) for s in states)
        return cls(np.ascontiguousarray(u, dtype=float), np.ascontiguousarray(t, dtype=float), theta,
                   np.zeros((n_rods, 2)))

    def copy(self) -> "Frames":
        """An independent copy (the compiled step advances frames in place)."""
        return Frames(self.u.copy(), self.t.copy(), self.theta.copy(), self.theta_end.copy())


class EndBodies(NamedTuple):
    """Clamps held by moving bodies: each such clamped edge's material director turns with
    its body. body: MuJoCo body id per rod and end (start, end), -1 where none, shape
    (n_rods, 2), int64. director: the clamp's material director in the body's frame,
    shape (n_rods, 2, 3)."""

    body: np.ndarray
    director: np.ndarray

    @classmethod
    def none(cls, n_rods: int) -> "EndBodies":
        return cls(np.full((n_rods, 2), -1, dtype=np.int64), np.zeros((n_rods, 2, 3)))


class Terms(NamedTuple):
    """What :func:`evaluate` fills in, per set (preallocate once with :meth:`empty`).

    energy: elastic energy [J], shape (n_rods,). grad: dE/dx [N], shape (n_vertices, 3).
    band: lower band of the PSD Hessian over the places in the solve order [N/m], shape
    (band_rows, 3 n_places). g_tw: d(total reference twist)/dx [1/m], shape
    (n_vertices, 3): the reduced twist term's Hessian is coef g g^T. lam: twisting moment
    [N m], coef: 2 / sum(l_k / beta) [N m] (0 unless both ends' frames are held, and for
    rods whose twist is solved by Newton's method), shape (n_rods,). end_moment: dE/dtheta
    of each rod's first and last edge [N m], the moments held ends resist, shape
    (n_rods, 2). strain: largest |edge strain| per rod, shape (n_rods,).
    """

    energy: np.ndarray
    grad: np.ndarray
    band: np.ndarray
    g_tw: np.ndarray
    lam: np.ndarray
    coef: np.ndarray
    end_moment: np.ndarray
    strain: np.ndarray

    @classmethod
    def empty(cls, n_rods: int, n_vertices: int, n_dofs: int, band_rows: int) -> "Terms":
        return cls(np.zeros(n_rods), np.zeros((n_vertices, 3)), np.zeros((band_rows, n_dofs)),
                   np.zeros((n_vertices, 3)), np.zeros(n_rods), np.zeros(n_rods), np.zeros((n_rods, 2)),
                   np.zeros(n_rods))


def evaluate(rods: RodSet, frames: Frames, x: np.ndarray, place: np.ndarray, out: Terms,
             ends: EndBodies, xmat: np.ndarray, strain_limit: float = np.inf, bands: np.ndarray | None = None,
             band_of_rod: np.ndarray | None = None, kernel=None) -> int:
    """Advance ``frames`` to positions ``x`` and fill ``out`` (one compiled call).

    x: vertex positions [m], shape (n_vertices, 3). place: each vertex's place in the
    solve order (its dofs are 3 place .. 3 place + 2), -1 for a held vertex, shape
    (n_vertices,), int64. ends: clamps on moving bodies; xmat: MuJoCo's body
    orientations (``data.xmat``), shape (n_bodies, 9). bands, band_of_rod: where rod i's
    Hessian goes, ``bands[band_of_rod[i]]`` (default: every rod into ``out.band``, the
    world's one band; :meth:`derods.Rod.step_terms` gives each rod a band of its own, with
    ``place`` local to each rod). kernel: a world's call of the compiled step
    (:func:`derods._numba.parallel.kernel`: on threads, chunk by chunk, for a world of many
    rods; the same results); default: one call for all rods. Returns the index of the
    first rod whose edge strain is not finite or exceeds ``strain_limit``, else -1.
    """
    global _rods_step
    if kernel is None:
        if _rods_step is None:
            from ._numba.calls import Bound
            from ._numba.step import rods_step

            _rods_step = Bound(rods_step)
        kernel = _rods_step
    if bands is None:
        bands, band_of_rod = out.band[None], np.zeros(rods.n_rods, dtype=np.int64)
    out.strain[:] = strain_limit
    return kernel(rods, ends, frames, x, xmat, place, bands, band_of_rod, out)


#: The compiled rod step, called without retyping the same bundles (derods._numba.calls).
_rods_step = None
