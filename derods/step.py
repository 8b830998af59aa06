"""One step's terms for a set of rods: transport, twist, forces and the PSD band, in one call.

What an implicit step needs from every rod of a world, computed once per step:
the reference frames transported in time to the new tangents (Bergou et al.
2010, 3.1), the frames of clamps held by moving bodies, the quasistatic twist
(Bergou et al. 2008, 4.4), the gradient of stretch + bending + twist, and the
positive semi-definite Hessian as one lower band over the dofs in their solve
order. Rods of any sizes are laid end to end in flat arrays (:class:`RodSet`,
frozen; :class:`Frames`, the state), so one compiled call
(:func:`derods._numba.step.rods_step`) serves them all, and Python's work per
step does not grow with the number of rods.

The compiled path covers isotropic, naturally straight rods (open or closed).
Its oracle is the numpy path of :meth:`derods.rod.Rod.step_terms`
(``use_kernel=False``), held to it to round-off by tests/test_step.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .twist import TwistBoundary


@dataclass(frozen=True)
class RodSet:
    """Rods laid end to end: per-rod constants and offsets into flat per-vertex,
    per-edge and per-joint arrays (rod i owns vertices v_off[i]:v_off[i + 1], etc.).

    v_off, e_off, j_off: offsets, shape (n_rods + 1,), int64.
    rest_len: rest edge lengths [m], shape (n_edges,). vlen: vertex lengths l_k [m],
    shape (n_joints,). mbar: natural twist per joint [rad], shape (n_joints,).
    ks [N], alpha [N m^2], beta [N m^2]: stiffnesses, shape (n_rods,).
    compiled (the compiled step covers the rod: isotropic and naturally straight; the
    others are left to :meth:`derods.rod.Rod.step_terms`), closed, has_twist (the rod
    carries the twist term), clamped (both ends' frames held, or a ring's total twist
    imposed), anchor_last (only the last edge's frame held): shape (n_rods,), bool. theta_first, theta_last [rad]: held angles of the end edges
    (0 where not held); total_twist [rad]: a ring's imposed twist; shape (n_rods,).
    """

    v_off: np.ndarray
    e_off: np.ndarray
    j_off: np.ndarray
    rest_len: np.ndarray
    vlen: np.ndarray
    mbar: np.ndarray
    ks: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    compiled: np.ndarray
    closed: np.ndarray
    has_twist: np.ndarray
    clamped: np.ndarray
    anchor_last: np.ndarray
    theta_first: np.ndarray
    theta_last: np.ndarray
    total_twist: np.ndarray

    @classmethod
    def of(cls, rods: Sequence, boundaries: Sequence[TwistBoundary | None] | None = None) -> "RodSet":
        """The set of ``rods`` (:class:`derods.Rod`, each one rod or a batch of equal
        rods, expanded in order); boundaries: per rod, a boundary replacing its own."""
        if boundaries is None:
            boundaries = [None] * len(rods)
        nv, ne, nj, cols = [], [], [], {k: [] for k in ("rest_len", "vlen", "mbar")}
        per_rod = {k: [] for k in ("ks", "alpha", "beta", "compiled", "closed", "has_twist", "clamped",
                                   "anchor_last", "theta_first", "theta_last", "total_twist")}
        for rod, bd in zip(rods, boundaries):
            bd = rod.boundary if bd is None else bd
            batch = int(np.prod(rod.rest_x.shape[:-2], dtype=int))
            n_j = rod.vlen.shape[-1]
            rest_len = np.broadcast_to(rod.rest_len, rod.rest_x.shape[:-2] + (rod.n_edges,)).reshape(batch, -1)
            vlen = np.broadcast_to(rod.vlen, rod.rest_x.shape[:-2] + (n_j,)).reshape(batch, -1)
            mbar = np.broadcast_to(rod.mbar, rod.rest_x.shape[:-2] + (n_j,)).reshape(batch, -1)
            for b in range(batch):
                nv.append(rod.n_vertices)
                ne.append(rod.n_edges)
                nj.append(n_j)
                cols["rest_len"].append(rest_len[b])
                cols["vlen"].append(vlen[b])
                cols["mbar"].append(mbar[b])
                per_rod["ks"].append(rod.ks)
                per_rod["alpha"].append(rod.material.alpha)
                per_rod["beta"].append(rod.material.beta)
                per_rod["compiled"].append(rod.has_kernel)
                per_rod["closed"].append(rod.closed)
                per_rod["has_twist"].append("twist" in rod.active_terms)
                per_rod["clamped"].append(bd.kind in ("clamped", "ring"))
                per_rod["anchor_last"].append(not rod.closed and bd.kind == "free" and bd.theta_first is None
                                              and bd.theta_last is not None)
                per_rod["theta_first"].append(bd.theta_first or 0.0)
                per_rod["theta_last"].append(bd.theta_last or 0.0)
                per_rod["total_twist"].append(bd.total_twist)
        off = lambda counts: np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)  # noqa: E731
        flat = {k: np.ascontiguousarray(np.concatenate(v), dtype=float) for k, v in cols.items()}
        bools = ("compiled", "closed", "has_twist", "clamped", "anchor_last")
        rod_arrays = {k: np.array(v, dtype=bool if k in bools else float) for k, v in per_rod.items()}
        return cls(off(nv), off(ne), off(nj), **flat, **rod_arrays)

    @property
    def n_rods(self) -> int:
        return len(self.v_off) - 1

    @property
    def n_vertices(self) -> int:
        return int(self.v_off[-1])

    @property
    def n_edges(self) -> int:
        return int(self.e_off[-1])


@dataclass
class Frames:
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


@dataclass(frozen=True)
class EndBodies:
    """Clamps held by moving bodies: each such clamped edge's material director turns with
    its body. body: MuJoCo body id per rod and end (start, end), -1 where none, shape
    (n_rods, 2), int64. director: the clamp's material director in the body's frame,
    shape (n_rods, 2, 3)."""

    body: np.ndarray
    director: np.ndarray

    @classmethod
    def none(cls, n_rods: int) -> "EndBodies":
        return cls(np.full((n_rods, 2), -1, dtype=np.int64), np.zeros((n_rods, 2, 3)))


@dataclass
class Terms:
    """What :func:`evaluate` fills in, per set (preallocate once with :meth:`empty`).

    energy: elastic energy [J], shape (n_rods,). grad: dE/dx [N], shape (n_vertices, 3).
    band: lower band of the PSD Hessian over the places in the solve order [N/m], shape
    (band_rows, 3 n_places). g_tw: d(total reference twist)/dx [1/m], shape
    (n_vertices, 3): the reduced twist term's Hessian is coef g g^T. lam: twisting moment
    [N m], coef: 2 / sum(l_k / beta) [N m] (0 unless both ends' frames are held),
    strain: largest |edge strain| per rod, shape (n_rods,).
    """

    energy: np.ndarray
    grad: np.ndarray
    band: np.ndarray
    g_tw: np.ndarray
    lam: np.ndarray
    coef: np.ndarray
    strain: np.ndarray

    @classmethod
    def empty(cls, n_rods: int, n_vertices: int, n_dofs: int, band_rows: int) -> "Terms":
        return cls(np.zeros(n_rods), np.zeros((n_vertices, 3)), np.zeros((band_rows, n_dofs)),
                   np.zeros((n_vertices, 3)), np.zeros(n_rods), np.zeros(n_rods), np.zeros(n_rods))


def evaluate(rods: RodSet, frames: Frames, x: np.ndarray, place: np.ndarray, out: Terms,
             ends: EndBodies, xmat: np.ndarray, strain_limit: float = np.inf, bands: np.ndarray | None = None,
             band_of_rod: np.ndarray | None = None) -> int:
    """Advance ``frames`` to positions ``x`` and fill ``out`` (one compiled call).

    x: vertex positions [m], shape (n_vertices, 3). place: each vertex's place in the
    solve order (its dofs are 3 place .. 3 place + 2), -1 for a held vertex, shape
    (n_vertices,), int64. ends: clamps on moving bodies; xmat: MuJoCo's body
    orientations (``data.xmat``), shape (n_bodies, 9). Rods the compiled step does not
    cover (``rods.compiled`` False) are left untouched. bands, band_of_rod: where rod i's
    Hessian goes, ``bands[band_of_rod[i]]`` (default: every rod into ``out.band``, the
    world's one band; :meth:`derods.Rod.step_terms` gives each rod a band of its own, with
    ``place`` local to each rod). Returns the index of the first rod whose edge strain is
    not finite or exceeds ``strain_limit``, else -1.
    """
    from ._numba.step import rods_step

    if bands is None:
        bands, band_of_rod = out.band[None], np.zeros(rods.n_rods, dtype=np.int64)
    out.strain[:] = strain_limit
    return rods_step(x, rods.v_off, rods.e_off, rods.j_off, rods.rest_len, rods.vlen, rods.mbar, rods.ks,
                     rods.alpha, rods.beta, rods.compiled, rods.closed, rods.has_twist, rods.clamped, rods.anchor_last,
                     rods.theta_first, rods.theta_last, rods.total_twist, ends.body, ends.director,
                     frames.theta_end, xmat, place, band_of_rod, frames.u, frames.t, frames.theta, out.grad,
                     bands, out.g_tw, out.energy, out.lam, out.coef, out.strain)


