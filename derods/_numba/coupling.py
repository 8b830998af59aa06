"""Compiled moves between MuJoCo's arrays and derods' (see :mod:`derods.sim.layout`):
vertex positions in, forces and accelerations out, the divergence check, and the
rods' reaction on the bodies that hold them. Each is one pass over the rod dofs,
so none grows into many small numpy calls per step."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def gather_positions(x0, qpos, qpos_adr, free_vertex, xpos, moved_vertex, moved_body, x):
    """x = x0, with each free vertex displaced by its three slide joints and each vertex
    held by a moving body at that body's position (MuJoCo's xpos, shape (n_bodies, 3))."""
    x[:] = x0
    for p in range(len(free_vertex)):
        v, q = free_vertex[p], qpos_adr[p]
        for a in range(3):
            x[v, a] += qpos[q + a]
    for h in range(len(moved_vertex)):
        for a in range(3):
            x[moved_vertex[h], a] = xpos[moved_body[h], a]


@nb.njit(cache=True)
def write_applied(dofs, mass, acc, other, qfrc_applied):
    """qfrc_applied[dofs] = M acc - other: the force that makes MuJoCo's unconstrained
    acceleration of the rod dofs equal acc [m/s^2] (other [N]: what MuJoCo adds itself)."""
    for k in range(len(dofs)):
        qfrc_applied[dofs[k]] = mass[k] * acc[k] - other[k]


@nb.njit(cache=True)
def write_acceleration(dofs, mass, a, qacc, qfrc_smooth, qfrc_constraint, with_force):
    """qacc[dofs] = a; with_force: also qfrc_constraint[dofs] = M a - qfrc_smooth[dofs] (the
    implicit integrators, and Euler's with damped dofs, re-solve from forces; rod dofs carry
    no damping or coupling there, so this force reproduces a)."""
    for k in range(len(dofs)):
        qacc[dofs[k]] = a[k]
        if with_force:
            qfrc_constraint[dofs[k]] = mass[k] * a[k] - qfrc_smooth[dofs[k]]


@nb.njit(cache=True)
def fastest_dof(qvel, dofs, max_speed):
    """-1 if every rod dof moves at most max_speed [m/s] (and is finite); else the local
    index of the first non-finite velocity, or of the fastest."""
    worst, speed = -1, max_speed
    for k in range(len(dofs)):
        s = abs(qvel[dofs[k]])
        if not s == s or s == np.inf:
            return k
        if s > speed:
            worst, speed = k, s
    return worst


@nb.njit(cache=True)
def holder_wrench(x, grad, t, held_vertex, held_slot, clamp_slot, clamp_edge, end_moment, point, force, torque):
    """The rods' force [N] and torque [N m] about ``point`` (n_slots, 3) on each holding
    body ("slot"): -grad at each held vertex, and at each clamp on a body the twisting
    moment -dE/dtheta about its edge's tangent t (its end_moment [N m])."""
    force[:] = 0.0
    torque[:] = 0.0
    for h in range(len(held_vertex)):
        v, s = held_vertex[h], held_slot[h]
        f0, f1, f2 = -grad[v, 0], -grad[v, 1], -grad[v, 2]
        r0, r1, r2 = x[v, 0] - point[s, 0], x[v, 1] - point[s, 1], x[v, 2] - point[s, 2]
        force[s, 0] += f0
        force[s, 1] += f1
        force[s, 2] += f2
        torque[s, 0] += r1 * f2 - r2 * f1
        torque[s, 1] += r2 * f0 - r0 * f2
        torque[s, 2] += r0 * f1 - r1 * f0
    for c in range(len(clamp_slot)):
        s, e = clamp_slot[c], clamp_edge[c]
        for a in range(3):
            torque[s, a] -= end_moment[c] * t[e, a]


@nb.njit(cache=True)
def free_band_into(bands, first, dof_off, band):
    """band (rows, n) <- the world's lower band over the free dofs, sliced from the rods'
    all-vertex bands (n_rods, rows, 3 max_vertices): rod i's free vertices start at vertex
    place first[i] of its own band and at dof dof_off[i] of the world's (the same order);
    entries reaching past a rod's free dofs (to held vertices, or to the next rod) are 0."""
    band[:] = 0.0
    rows = band.shape[0]
    for i in range(len(first)):
        c0, nf, a = dof_off[i], dof_off[i + 1] - dof_off[i], 3 * first[i]
        for d in range(rows):
            for j in range(nf - d):
                band[d, c0 + j] = bands[i, d, a + j]


@nb.njit(cache=True)
def gather_into(bands, band, d, j, row, col, out):
    """out (zeroed first) <- bands[band[p], d[p], j[p]] at (row[p], col[p]) for every p: the
    blocks of symmetric matrices kept as lower bands, placed as
    :func:`derods.sim.holders.band_entries` indexed them."""
    out[:] = 0.0
    for p in range(len(band)):
        out[row[p], col[p]] = bands[band[p], d[p], j[p]]


@nb.njit(cache=True)
def band_product_into(bands, band, d, j, row, col, vec, out):
    """out[row[p]] += bands[band[p], d[p], j[p]] vec[col[p]] for every p: a block of symmetric
    matrices kept as lower bands, placed as :func:`derods.sim.holders.band_entries` indexed
    them, times vec (without making the block dense)."""
    for p in range(len(band)):
        out[row[p]] += bands[band[p], d[p], j[p]] * vec[col[p]]
