"""The implicit step's work on either side of MuJoCo's forward pass and derods' contact
solve, each as one compiled call: before, the prediction (:func:`predict`: the rods'
positions from MuJoCo's state, their terms and band, the unconstrained implicit
acceleration a0, the strain limit on it, the force that hands a0 to MuJoCo); after, the
conclusion (:func:`conclude`: the strain limit on the contact solve's acceleration with
the touching vertices made lighter, and that acceleration handed to MuJoCo's integrator).

Each runs the kernels the step otherwise calls one by one
(:mod:`derods._numba.coupling`, :func:`derods._numba.step.rods_step`,
:func:`derods._numba.implicit.unconstrained_step`, :func:`derods._numba.projection.limit_strain`,
:func:`derods._numba.projection.touching_into`), in the same order on the same arrays, so
the results are the same to the bit; as one call the step unboxes its bundles once and runs
no Python between them. A world takes them where nothing else must happen between the
kernels (:meth:`derods.sim.integrators.Implicit.step`: no held vertices on moving bodies,
reactions, riders, prescribed vertices, holders with dofs or threads; for the conclusion,
no static friction either).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .coupling import gather_positions, write_acceleration, write_applied
from .implicit import StepParams, System, Places, unconstrained_step
from .projection import limit_strain, touching_into
from .step import rods_step


class PredictArrays(NamedTuple):
    """What :func:`predict` reads and writes, held once by a world's step
    (:class:`derods.sim.integrators.Implicit`), in the order the kernels take them.

    Positions (:func:`derods._numba.coupling.gather_positions`): x0, qpos, qpos_adr,
    free_vertex, xpos, moved_vertex, moved_body, x (n_vertices, 3) [m]. The rods' terms
    (:func:`derods._numba.step.rods_step`): rods, ends, frames, xmat, place, bands,
    band_of_rod, terms. The unconstrained solve (:func:`derods._numba.implicit.unconstrained_step`):
    system, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0 (n,) [m/s^2]. The
    strain limit (:func:`derods._numba.projection.limit_strain`): inv_mass (n_vertices,)
    [1/kg], limited (n_rods,), xp (n_vertices, 3) scratch. MuJoCo's side
    (:func:`derods._numba.coupling.write_applied`): dofs, mass, qfrc_applied."""

    x0: np.ndarray
    qpos: np.ndarray
    qpos_adr: np.ndarray
    free_vertex: np.ndarray
    xpos: np.ndarray
    moved_vertex: np.ndarray
    moved_body: np.ndarray
    x: np.ndarray
    rods: NamedTuple
    ends: NamedTuple
    frames: NamedTuple
    xmat: np.ndarray
    place: np.ndarray
    bands: np.ndarray
    band_of_rod: np.ndarray
    terms: NamedTuple
    system: System
    places: Places
    params: StepParams
    qvel: np.ndarray
    xfrc_applied: np.ndarray
    v: np.ndarray
    other: np.ndarray
    rhs: np.ndarray
    kv: np.ndarray
    a0: np.ndarray
    inv_mass: np.ndarray
    limited: np.ndarray
    xp: np.ndarray
    dofs: np.ndarray
    mass: np.ndarray
    qfrc_applied: np.ndarray


class ConcludeArrays(NamedTuple):
    """What :func:`conclude` reads and writes (only those: numba unboxes every array of a
    bundle at each call). The strain limit's: x (n_vertices, 3) [m], v_off, e_off, rest_len
    (the rods' :class:`derods.step.RodSet` fields), place, v (n,) [m/s], h [s], inv_mass
    (n_vertices,) [1/kg] with free_vertex to make the touching ones lighter into touching
    (n_vertices,) scratch, limited (n_rods,), xp (n_vertices, 3) scratch; MuJoCo's
    (:func:`derods._numba.coupling.write_acceleration`): dofs, mass, qacc, qfrc_smooth,
    qfrc_constraint, with_force (bool)."""

    x: np.ndarray
    v_off: np.ndarray
    e_off: np.ndarray
    rest_len: np.ndarray
    place: np.ndarray
    v: np.ndarray
    h: float
    inv_mass: np.ndarray
    free_vertex: np.ndarray
    touching: np.ndarray
    limited: np.ndarray
    xp: np.ndarray
    dofs: np.ndarray
    mass: np.ndarray
    qacc: np.ndarray
    qfrc_smooth: np.ndarray
    qfrc_constraint: np.ndarray
    with_force: bool


@nb.njit(cache=True)
def predict(s, max_strain, strain_limit, tol, max_iter):
    """x from MuJoCo's qpos and xpos; the rods' terms, with the strain check against
    max_strain; a0; the strain limit on a0 (vertex weights s.inv_mass, rods flagged
    s.limited, strain_limit inf: none; the projection to tol in max_iter iterations);
    qfrc_applied on the rod dofs (s: :class:`PredictArrays`). Returns (the first rod strained
    beyond max_strain or -1: then nothing after the terms ran; rods projected). Raises
    ValueError if A or a projection's matrix is not positive definite."""
    gather_positions(s.x0, s.qpos, s.qpos_adr, s.free_vertex, s.xpos, s.moved_vertex, s.moved_body, s.x)
    s.terms.strain[:] = max_strain
    bad = rods_step(s.rods, s.ends, s.frames, s.x, s.xmat, s.place, s.bands, s.band_of_rod, s.terms)
    if bad >= 0:
        return bad, 0
    unconstrained_step(s.system, s.terms, s.places, s.params, s.qvel, s.xfrc_applied, s.v, s.other, s.rhs, s.kv,
                       s.a0)
    projected = 0
    if strain_limit < 1e300:
        projected = limit_strain(s.x, s.rods.v_off, s.rods.e_off, s.rods.rest_len, s.inv_mass, s.place, s.v, s.a0,
                                 s.params.h, s.limited, strain_limit, tol, max_iter, s.xp, s.x)[0]
    write_applied(s.dofs, s.mass, s.a0, s.other, s.qfrc_applied)
    return -1, projected


@nb.njit(cache=True)
def conclude(c, a, force, touching_weight, strain_limit, tol, max_iter):
    """After the contact solve: the strain limit on its acceleration a (n,) [m/s^2]
    (changed in place), the vertices its force (n,) [N] pushes on made ``touching_weight``
    times lighter, rods the projection leaves so projected again by their own masses
    (rods flagged c.limited; strain_limit inf: none); then a handed to MuJoCo's
    integrator (c: :class:`ConcludeArrays`). Returns the rods projected. Raises ValueError
    if a projection's matrix is not positive definite."""
    projected = 0
    if strain_limit < 1e300:
        touching_into(force, c.inv_mass, c.free_vertex, touching_weight, c.touching)
        projected, left = limit_strain(c.x, c.v_off, c.e_off, c.rest_len, c.touching, c.place, c.v, a, c.h,
                                       c.limited, strain_limit, tol, max_iter, c.xp, c.x)
        if left:
            more, left = limit_strain(c.x, c.v_off, c.e_off, c.rest_len, c.inv_mass, c.place, c.v, a, c.h,
                                      c.limited, strain_limit, tol, max_iter, c.xp, c.x)
            projected += more
    write_acceleration(c.dofs, c.mass, a, c.qacc, c.qfrc_smooth, c.qfrc_constraint, c.with_force)
    return projected
