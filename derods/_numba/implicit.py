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

from .banded import cholesky_into, matvec_into, solve_into
from .leaf import leaf


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


@leaf
def factor_system(system, m_coef, s):
    """A's band a_band = s k_band + diag(m_coef mass); lt its Cholesky factor (n, rows); for
    each twist term i: z[lo_i:hi_i] = B^-1 g_i (block-local), den_i = 1 + s c_i g_i.z_i;
    weights = (m_coef, s). The arrays are ``system``'s (:class:`System`)."""
    k_band, mass, a_band, lt, g, z = system.k_band, system.mass, system.a_band, system.lt, system.g, system.z
    tw_lo, tw_hi, tw_c, den = system.tw_lo, system.tw_hi, system.tw_c, system.den
    system.weights[0] = m_coef
    system.weights[1] = s
    rows, n = k_band.shape
    for d in range(rows):
        for j in range(n):
            a_band[d, j] = s * k_band[d, j]
    for j in range(n):
        a_band[0, j] += m_coef * mass[j]
    cholesky_into(a_band, lt)
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        acc = 0.0
        for j in range(lo, hi):
            z[j] = g[j]
        solve_into(lt, z, lo, hi)
        for j in range(lo, hi):
            acc += g[j] * z[j]
        den[i] = 1.0 + s * tw_c[i] * acc


@leaf
def sm_solve_into(system, x):
    """x <- A^-1 x in place (A factored, ``system`` a :class:`System`): a banded solve,
    then one Sherman-Morrison update per twist term within its rod's range (A's band is
    block diagonal)."""
    lt, g, z, den, s = system.lt, system.g, system.z, system.den, system.weights[1]
    tw_lo, tw_hi, tw_c = system.tw_lo, system.tw_hi, system.tw_c
    n = x.shape[0]
    solve_into(lt, x, 0, n)
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        gx = 0.0
        for j in range(lo, hi):
            gx += g[j] * x[j]
        f = s * tw_c[i] * gx / den[i]
        for j in range(lo, hi):
            x[j] -= z[j] * f


@nb.njit(cache=True)
def sm_solve_columns_into(system, x):
    """x <- A^-1 x for every column of x (n, m) in place, each as :func:`sm_solve_into`
    solves a vector (``system`` a :class:`System`)."""
    col = np.empty(x.shape[0])
    for c in range(x.shape[1]):
        col[:] = x[:, c]
        sm_solve_into(system, col)
        x[:, c] = col


@leaf
def k_matvec_into(system, w, y):
    """y = K w = K_band w + sum_i c_i g_i (g_i . w) (``system`` a :class:`System`)."""
    g, tw_lo, tw_hi, tw_c = system.g, system.tw_lo, system.tw_hi, system.tw_c
    matvec_into(system.k_band, w, y)
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        gw = 0.0
        for j in range(lo, hi):
            gw += g[j] * w[j]
        for j in range(lo, hi):
            y[j] += tw_c[i] * g[j] * gw


@leaf
def gather_dofs(per_vertex, free_vertex, out):
    """out[3 p + a] = per_vertex[free_vertex[p], a]: a per-vertex field on the free dofs."""
    for p in range(len(free_vertex)):
        v = free_vertex[p]
        for a in range(3):
            out[3 * p + a] = per_vertex[v, a]


@leaf
def twist_terms(system, terms, places):
    """The rods' twist terms into ``system`` (:class:`System`): each term's c from its rod's
    ``terms.coef`` and the directions g from ``terms.g_tw`` on the free dofs
    (:class:`derods.step.Terms`, :class:`Places`)."""
    tw_rod, tw_c, coef = system.tw_rod, system.tw_c, terms.coef
    for i in range(len(tw_rod)):
        tw_c[i] = coef[tw_rod[i]]
    gather_dofs(terms.g_tw, places.free_vertex, system.g)


@nb.njit(cache=True)
def unconstrained_step(system, terms, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0):
    """The implicit step without contact, for all rods: assemble and factor A, solve
    A a0 = F - a_m M v - (b + h) K v with F = -grad + gravity + the user's xfrc_applied.

    system (:class:`System`): k_band (rows, n) [N/m] the elastic band over the free dofs,
    filled and factored here. terms (:class:`derods.step.Terms`): grad, g_tw (n_vertices, 3),
    coef (n_rods,). places (:class:`Places`); params (:class:`StepParams`); qvel,
    xfrc_applied: MuJoCo's arrays. Out: v (n,) [m/s], other (n,) [N] (gravity + user
    force), a0 (n,) [m/s^2]; rhs, kv are scratch.
    """
    h, mass_damping, stiffness_damping, gravity = params
    free_vertex, free_body, dofs = places.free_vertex, places.free_body, places.dofs
    mass, grad = system.mass, terms.grad
    n = len(dofs)
    s = h * h + h * stiffness_damping
    twist_terms(system, terms, places)
    factor_system(system, 1.0 + h * mass_damping, s)
    for p in range(len(free_vertex)):
        b = free_body[p]
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
            other[k] = mass[k] * gravity[a] + xfrc_applied[b, a]
            rhs[k] = other[k] - grad[vtx, a] - mass_damping * mass[k] * v[k]
    k_matvec_into(system, v, kv)
    for k in range(n):
        rhs[k] -= (stiffness_damping + h) * kv[k]
        a0[k] = rhs[k]
    sm_solve_into(system, a0)


@nb.njit(cache=True, nogil=True)
def unconstrained_chunk(system, terms, places, params, qvel, xfrc_applied, v, other, rhs, kv, a0, part):
    """:func:`unconstrained_step` for one chunk of rods, ``part`` (a one-chunk
    :class:`derods._numba.parallel.Split`): the same step on their block of A, which is
    block diagonal over rods (their dofs [lo, hi), their twist terms t0 .. t1 - 1), through
    views of the world's arrays. Each rod's arithmetic is that of one step of all rods, and
    the call releases the GIL: the chunks of a world run at once on threads. (Entries of A
    that couple the block to the rest are +0; the whole matrix's factor, products and
    solves add or subtract only products with them, which leave every value as it is.)"""
    lo, hi, t0, t1 = part.dofs[0], part.dofs[1], part.twists[0], part.twists[1]
    block = System(system.k_band[:, lo:hi], system.mass[lo:hi], system.g[lo:hi], system.tw_rod[t0:t1],
                   system.tw_lo[t0:t1] - lo, system.tw_hi[t0:t1] - lo, system.tw_c[t0:t1], system.a_band[:, lo:hi],
                   system.lt[lo:hi], system.z[lo:hi], system.den[t0:t1], system.weights)
    mine = Places(places.free_vertex[lo // 3:hi // 3], places.free_body[lo // 3:hi // 3], places.dofs[lo:hi])
    unconstrained_step(block, terms, mine, params, qvel, xfrc_applied, v[lo:hi], other[lo:hi], rhs[lo:hi],
                       kv[lo:hi], a0[lo:hi])


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


@leaf
def twist_update_columns(system, ztw, zspan, cols):
    """Sherman-Morrison for each twist term of ``system`` (:class:`derods._numba.implicit.System`)
    in turn, on every column of cols (n, m): x -= z_i (s c_i g_i.x) / (1 + s c_i g_i.z_i),
    z_i = ztw[:, i] (B^-1 g_i), nonzero only in [zspan[i, 0], zspan[i, 1]) (its rod's
    dofs, and a rod a banded row joins to it: :func:`twist_spans`)."""
    g, tw_lo, tw_hi, tw_c, s = system.g, system.tw_lo, system.tw_hi, system.tw_c, system.weights[1]
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        gz = 0.0
        for j in range(lo, hi):
            gz += g[j] * ztw[j, i]
        sc = s * tw_c[i]
        for c in range(cols.shape[1]):
            gx = 0.0
            for j in range(lo, hi):
                gx += g[j] * cols[j, c]
            f = sc * gx / (1.0 + sc * gz)
            for j in range(zspan[i, 0], zspan[i, 1]):
                cols[j, c] -= ztw[j, i] * f


@leaf
def twist_spans(ztw, zspan):
    """Each column's nonzero range of ztw (n, T) into zspan (T, 2): B is block diagonal
    by rod, so B^-1 g_i is exactly zero beyond the rods a twist term's rod is banded with,
    and the updates skip only exact zeros (the same numbers, a hundred rods' worth of
    work less per solve in a pile)."""
    n = ztw.shape[0]
    for i in range(ztw.shape[1]):
        lo, hi = n, 0
        for j in range(n):
            if ztw[j, i] != 0.0:
                lo = min(lo, j)
                hi = j + 1
        zspan[i, 0], zspan[i, 1] = min(lo, hi), hi
