"""Compiled mirror of :mod:`derods.sim.implicit`: the implicit step matrix of all rods,
its factor and its solves, and the unconstrained step itself.

A = M (1 + h a_m) + s (K_band + sum_i c_i g_i g_i^T), s = h^2 + h b. The band of
all rods is block diagonal (rod after rod); each rank-one twist term lives in
one rod's dof range [lo_i, hi_i) and is handled by the Sherman-Morrison
formula with z_i = B^-1 g_i (B the banded part), which a block-diagonal B
confines to the same range.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .banded import cholesky_range, matvec_range, solve_into


class System(NamedTuple):
    """The implicit step's matrix A = m_coef M + s (K_band + sum_i c_i g_i g_i^T) over n
    dofs with T twist terms, and its factor (:class:`derods.sim.implicit.ImplicitSystem`
    holds one).

    k_band (rows, n): the band of K [N/m]; mass (n,) [kg]; g (n,): the twist directions of
    all rods laid end to end [1/m]; tw_rod, tw_lo, tw_hi (T,): each twist term's rod and dof
    range; tw_c (T,): its stiffness c [N m]. Written by :func:`factor_system`: a_band (A's
    band), lt (its Cholesky factor, column by column, shape (n, rows), see
    :mod:`derods._numba.banded`), z (n,) = B^-1 g per range, den (T,) = 1 + s c g.z, and
    weights (2,) = (m_coef, s), the weights of M and K that A was factored with.
    """

    k_band: np.ndarray
    mass: np.ndarray
    g: np.ndarray
    tw_rod: np.ndarray
    tw_lo: np.ndarray
    tw_hi: np.ndarray
    tw_c: np.ndarray
    a_band: np.ndarray
    lt: np.ndarray
    z: np.ndarray
    den: np.ndarray
    weights: np.ndarray


class Places(NamedTuple):
    """The rods' free vertices in the solve order (place p owns local dofs 3 p .. 3 p + 2):
    free_vertex, free_body (n / 3,), each place's vertex and MuJoCo body; dofs (n,), each
    local dof's MuJoCo dof (see :class:`derods.sim.layout.Layout`)."""

    free_vertex: np.ndarray
    free_body: np.ndarray
    dofs: np.ndarray


class StepParams(NamedTuple):
    """A step's frozen settings: its size h [s], the Rayleigh damping's mass_damping a_m
    [1/s] and stiffness_damping b [s], and gravity (3,) [m/s^2]."""

    h: float
    mass_damping: float
    stiffness_damping: float
    gravity: np.ndarray


@nb.njit(cache=True)
def factor_system(system, m_coef, s):
    """A's band a_band = s k_band + diag(m_coef mass); lt its Cholesky factor (n, rows); for
    each twist term i: z[lo_i:hi_i] = B^-1 g_i (block-local), den_i = 1 + s c_i g_i.z_i;
    weights = (m_coef, s). The arrays are ``system``'s (:class:`System`). Raises ValueError
    if A is not positive definite."""
    system.weights[0] = m_coef
    system.weights[1] = s
    if not factor_range(system, m_coef, s, 0, system.k_band.shape[1], 0, len(system.tw_lo)):
        raise ValueError("matrix is not positive definite")


@nb.njit(cache=True)
def factor_range(system, m_coef, s, lo, hi, t0, t1):
    """:func:`factor_system` on the diagonal block of dofs [lo, hi) and its twist terms
    t0 .. t1 - 1 (weights not written). False if A is not positive definite there."""
    k_band, mass, a_band, lt, g, z = system.k_band, system.mass, system.a_band, system.lt, system.g, system.z
    tw_lo, tw_hi, tw_c, den = system.tw_lo, system.tw_hi, system.tw_c, system.den
    rows = k_band.shape[0]
    for d in range(rows):
        for j in range(lo, hi):
            a_band[d, j] = s * k_band[d, j]
    for j in range(lo, hi):
        a_band[0, j] += m_coef * mass[j]
    if not cholesky_range(a_band, lt, lo, hi):
        return False
    for i in range(t0, t1):
        r0, r1 = tw_lo[i], tw_hi[i]
        acc = 0.0
        for j in range(r0, r1):
            z[j] = g[j]
        solve_into(lt, z, r0, r1)
        for j in range(r0, r1):
            acc += g[j] * z[j]
        den[i] = 1.0 + s * tw_c[i] * acc
    return True


@nb.njit(cache=True)
def sm_solve_into(system, x):
    """x <- A^-1 x in place (A factored, ``system`` a :class:`System`): a banded solve,
    then one Sherman-Morrison update per twist term within its rod's range (A's band is
    block diagonal)."""
    sm_solve_range(system, x, 0, x.shape[0], 0, len(system.tw_lo))


@nb.njit(cache=True)
def sm_solve_range(system, x, lo, hi, t0, t1):
    """:func:`sm_solve_into` on the diagonal block of dofs [lo, hi) with its twist terms
    t0 .. t1 - 1."""
    lt, g, z, den, s = system.lt, system.g, system.z, system.den, system.weights[1]
    tw_lo, tw_hi, tw_c = system.tw_lo, system.tw_hi, system.tw_c
    solve_into(lt, x, lo, hi)
    for i in range(t0, t1):
        r0, r1 = tw_lo[i], tw_hi[i]
        gx = 0.0
        for j in range(r0, r1):
            gx += g[j] * x[j]
        f = s * tw_c[i] * gx / den[i]
        for j in range(r0, r1):
            x[j] -= z[j] * f


@nb.njit(cache=True)
def k_matvec_into(system, w, y):
    """y = K w = K_band w + sum_i c_i g_i (g_i . w) (``system`` a :class:`System`)."""
    k_matvec_range(system, w, y, 0, system.k_band.shape[1], 0, len(system.tw_lo))


@nb.njit(cache=True)
def k_matvec_range(system, w, y, lo, hi, t0, t1):
    """:func:`k_matvec_into` on the diagonal block of dofs [lo, hi) with its twist terms
    t0 .. t1 - 1: y[lo:hi] from w[lo:hi]."""
    g, tw_lo, tw_hi, tw_c = system.g, system.tw_lo, system.tw_hi, system.tw_c
    matvec_range(system.k_band, w, y, lo, hi)
    for i in range(t0, t1):
        r0, r1 = tw_lo[i], tw_hi[i]
        gw = 0.0
        for j in range(r0, r1):
            gw += g[j] * w[j]
        for j in range(r0, r1):
            y[j] += tw_c[i] * g[j] * gw


@nb.njit(cache=True)
def twist_terms(system, terms, places):
    """The rods' twist terms into ``system`` (:class:`System`): each term's c from its rod's
    ``terms.coef`` and the directions g from ``terms.g_tw`` on the free dofs
    (:class:`derods.step.Terms`, :class:`Places`)."""
    twist_terms_range(system, terms, places, 0, len(places.dofs), 0, len(system.tw_rod))


@nb.njit(cache=True)
def twist_terms_range(system, terms, places, lo, hi, t0, t1):
    """:func:`twist_terms` for the dofs [lo, hi) (whole places) and the twist terms
    t0 .. t1 - 1."""
    tw_rod, tw_c, coef, g, g_tw, free_vertex = system.tw_rod, system.tw_c, terms.coef, system.g, terms.g_tw, \
        places.free_vertex
    for i in range(t0, t1):
        tw_c[i] = coef[tw_rod[i]]
    for p in range(lo // 3, hi // 3):
        v = free_vertex[p]
        for a in range(3):
            g[3 * p + a] = g_tw[v, a]


@nb.njit(cache=True, nogil=True)
def unconstrained_step(system, terms, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0, split):
    """The implicit step without contact, for all rods: assemble and factor A, solve
    A a0 = F - a_m M v - (b + h) K v with F = -grad + gravity + the user's xfrc_applied.

    system (:class:`System`): k_band (rows, n) [N/m] the elastic band over the free dofs,
    filled and factored here. terms (:class:`derods.step.Terms`): grad, g_tw (n_vertices, 3),
    coef (n_rods,). places (:class:`Places`); params (:class:`StepParams`); qvel,
    xfrc_applied: MuJoCo's arrays. Out: v (n,) [m/s], other (n,) [N] (gravity + user
    force), a0 (n,) [m/s^2]; rhs, kv are scratch. split
    (:class:`derods._numba.parallel.Split`): A is block diagonal over rods, so each chunk of
    whole rods is solved on its own (:func:`unconstrained_chunk`), each rod's arithmetic
    as in one solve of them all; a call may take some of the chunks, and calls for the
    others run at once on other threads (it releases the GIL). Raises ValueError if A is
    not positive definite.
    """
    h, mass_damping, stiffness_damping = params.h, params.mass_damping, params.stiffness_damping
    system.weights[0] = 1.0 + h * mass_damping
    system.weights[1] = h * h + h * stiffness_damping
    for c in range(len(split.dofs) - 1):
        if not unconstrained_chunk(system, terms, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0, split, c):
            raise ValueError("matrix is not positive definite")


@nb.njit(cache=True)
def unconstrained_chunk(system, terms, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0, split, c):
    """:func:`unconstrained_step` on chunk c of ``split``: its dofs [lo, hi) and twist terms
    t0 .. t1 - 1, with A's weights already in ``system.weights``. False (the rest of the
    chunk left undone) if A is not positive definite there."""
    h, mass_damping, stiffness_damping, gravity = params
    free_vertex, free_body, dofs = places.free_vertex, places.free_body, places.dofs
    mass, grad = system.mass, terms.grad
    lo, hi, t0, t1 = split.dofs[c], split.dofs[c + 1], split.twists[c], split.twists[c + 1]
    twist_terms_range(system, terms, places, lo, hi, t0, t1)
    if not factor_range(system, system.weights[0], system.weights[1], lo, hi, t0, t1):
        return False
    for p in range(lo // 3, hi // 3):
        b = free_body[p]
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
            other[k] = mass[k] * gravity[a] + xfrc_applied[b, a]
            rhs[k] = other[k] - grad[vtx, a] - mass_damping * mass[k] * v[k]
    k_matvec_range(system, v, kv, lo, hi, t0, t1)
    for k in range(lo, hi):
        rhs[k] -= (stiffness_damping + h) * kv[k]
        a0[k] = rhs[k]
    sm_solve_range(system, a0, lo, hi, t0, t1)
    return True


@nb.njit(cache=True)
def explicit_force(system, terms, places, params, qvel, v, kv, qfrc_applied):
    """The explicit step's force on the rod dofs, -grad - a_m M v - b K v [N], written into
    MuJoCo's qfrc_applied (K from ``system``'s k_band and ``terms``' twist terms; the
    damping from ``params``, :class:`StepParams`)."""
    mass_damping, stiffness_damping = params.mass_damping, params.stiffness_damping
    free_vertex, dofs, mass, grad = places.free_vertex, places.dofs, system.mass, terms.grad
    for p in range(len(free_vertex)):
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
    if stiffness_damping:
        twist_terms(system, terms, places)
        k_matvec_into(system, v, kv)
    for p in range(len(free_vertex)):
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            f = -grad[vtx, a] - mass_damping * mass[k] * v[k]
            if stiffness_damping:
                f -= stiffness_damping * kv[k]
            qfrc_applied[dofs[k]] = f
