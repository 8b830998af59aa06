"""Compiled mirror of :mod:`derods.sim.implicit`: the implicit step matrix of all rods,
its factor and its solves, and the unconstrained step itself.

A = M (1 + h a_m) + s (K_band + sum_i c_i g_i g_i^T), s = h^2 + h b. The band of
all rods is block diagonal (rod after rod); each rank-one twist term lives in
one rod's dof range [lo_i, hi_i) and is handled by the Sherman-Morrison
formula with z_i = B^-1 g_i (B the banded part), which a block-diagonal B
confines to the same range.
"""

from __future__ import annotations

import numba as nb

from .banded import cholesky_into, matvec_into, solve_into


@nb.njit(cache=True)
def factor_system(k_band, mass, m_coef, s, a_band, lt, g, tw_lo, tw_hi, tw_c, z, den):
    """a_band = s k_band + diag(m_coef mass); lt its Cholesky factor (n, rows); for each twist term
    i: z[lo_i:hi_i] = B^-1 g_i (block-local), den_i = 1 + s c_i g_i.z_i."""
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


@nb.njit(cache=True)
def sm_solve_into(lt, g, tw_lo, tw_hi, tw_c, s, z, den, x):
    """x <- A^-1 x in place: a banded solve, then one Sherman-Morrison update per twist
    term within its rod's range (A's band is block diagonal)."""
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
def k_matvec_into(k_band, g, tw_lo, tw_hi, tw_c, w, y):
    """y = K w = K_band w + sum_i c_i g_i (g_i . w)."""
    matvec_into(k_band, w, y)
    for i in range(len(tw_lo)):
        lo, hi = tw_lo[i], tw_hi[i]
        gw = 0.0
        for j in range(lo, hi):
            gw += g[j] * w[j]
        for j in range(lo, hi):
            y[j] += tw_c[i] * g[j] * gw


@nb.njit(cache=True)
def gather_dofs(per_vertex, free_vertex, out):
    """out[3 p + a] = per_vertex[free_vertex[p], a]: a per-vertex field on the free dofs."""
    for p in range(len(free_vertex)):
        v = free_vertex[p]
        for a in range(3):
            out[3 * p + a] = per_vertex[v, a]


@nb.njit(cache=True)
def unconstrained_step(k_band, grad, g_tw, coef, rod_tw, tw_lo, tw_hi, tw_c, free_vertex, free_body, dofs,
                       mass, qvel, xfrc_applied, gravity, h, mass_damping, stiffness_damping, a_band, lt, g,
                       z, den, v, other, rhs, kv, a0):
    """The implicit step without contact, for all rods: assemble and factor A, solve
    A a0 = F - a_m M v - (b + h) K v with F = -grad + gravity + the user's xfrc_applied.

    k_band (rows, n) [N/m]: the elastic band over the free dofs. grad, g_tw (n_vertices, 3);
    coef (n_rods,); rod_tw (n_tw,): the rod of each twist term. free_vertex, free_body
    (n / 3,): vertex and MuJoCo body of each place; dofs (n,): MuJoCo dofs; mass (n,) [kg];
    qvel, xfrc_applied: MuJoCo's arrays; gravity (3,) [m/s^2]. Out: a_band, lt, g, z,
    den (the factored system), v (n,) [m/s], other (n,) [N] (gravity + user force),
    a0 (n,) [m/s^2]; rhs, kv are scratch.
    """
    n = len(dofs)
    s = h * h + h * stiffness_damping
    for i in range(len(rod_tw)):
        tw_c[i] = coef[rod_tw[i]]
    gather_dofs(g_tw, free_vertex, g)
    factor_system(k_band, mass, 1.0 + h * mass_damping, s, a_band, lt, g, tw_lo, tw_hi, tw_c, z, den)
    for p in range(len(free_vertex)):
        b = free_body[p]
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
            other[k] = mass[k] * gravity[a] + xfrc_applied[b, a]
            rhs[k] = other[k] - grad[vtx, a] - mass_damping * mass[k] * v[k]
    k_matvec_into(k_band, g, tw_lo, tw_hi, tw_c, v, kv)
    for k in range(n):
        rhs[k] -= (stiffness_damping + h) * kv[k]
        a0[k] = rhs[k]
    sm_solve_into(lt, g, tw_lo, tw_hi, tw_c, s, z, den, a0)


@nb.njit(cache=True)
def explicit_force(k_band, grad, g_tw, coef, rod_tw, tw_lo, tw_hi, tw_c, free_vertex, dofs, mass, qvel,
                   mass_damping, stiffness_damping, g, v, kv, qfrc_applied):
    """The explicit step's force on the rod dofs, -grad - a_m M v - b K v [N], written into
    MuJoCo's qfrc_applied."""
    for p in range(len(free_vertex)):
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
    if stiffness_damping:
        for i in range(len(rod_tw)):
            tw_c[i] = coef[rod_tw[i]]
        gather_dofs(g_tw, free_vertex, g)
        k_matvec_into(k_band, g, tw_lo, tw_hi, tw_c, v, kv)
    for p in range(len(free_vertex)):
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            f = -grad[vtx, a] - mass_damping * mass[k] * v[k]
            if stiffness_damping:
                f -= stiffness_damping * kv[k]
            qfrc_applied[dofs[k]] = f
