"""Compiled mirror of :mod:`derods.sim.projection`: fast projection of open rods onto
their rest edge lengths (Goldenthal et al. 2007, Algorithm 1), one rod or all of a
world's in one call."""

from __future__ import annotations

import numba as nb
import numpy as np

from .banded import cholesky_into, solve_into


@nb.njit(cache=True)
def project_rod(x, inv_mass, rest_len, tol, max_iter):
    """Project x (n_vertices, 3) in place; returns the iterations used, or -1 (with the
    last strain left in x's distance from the manifold) if it did not converge."""
    nv = x.shape[0]
    lo, hi = -1, -1
    for j in range(nv - 1):
        if inv_mass[j] + inv_mass[j + 1] > 0:
            if lo < 0:
                lo = j
            hi = j + 1
    if lo < 0:
        return 0
    m = hi - lo
    c = np.empty(m)
    gvec = np.empty((m, 3))
    ab = np.zeros((2, m))
    lt = np.zeros((m, 2))
    for it in range(max_iter + 1):
        worst = 0.0
        for j in range(m):
            e0 = x[lo + j + 1, 0] - x[lo + j, 0]
            e1 = x[lo + j + 1, 1] - x[lo + j, 1]
            e2 = x[lo + j + 1, 2] - x[lo + j, 2]
            rest = rest_len[lo + j]
            c[j] = (e0 * e0 + e1 * e1 + e2 * e2) / rest - rest
            worst = max(worst, abs(c[j] / rest))
            gvec[j, 0], gvec[j, 1], gvec[j, 2] = 2.0 * e0 / rest, 2.0 * e1 / rest, 2.0 * e2 / rest
        if worst < tol:
            return it
        if it == max_iter:
            break
        for j in range(m):
            w0, w1 = inv_mass[lo + j], inv_mass[lo + j + 1]
            ab[0, j] = (gvec[j, 0] ** 2 + gvec[j, 1] ** 2 + gvec[j, 2] ** 2) * (w0 + w1)
            if j < m - 1:
                ab[1, j] = -(gvec[j, 0] * gvec[j + 1, 0] + gvec[j, 1] * gvec[j + 1, 1]
                             + gvec[j, 2] * gvec[j + 1, 2]) * w1
            else:
                ab[1, j] = 0.0
        cholesky_into(ab, lt)
        solve_into(lt, c, 0, m)  # c <- dlambda
        for j in range(m):
            for a in range(3):
                f = gvec[j, a] * c[j]
                x[lo + j + 1, a] -= inv_mass[lo + j + 1] * f
                x[lo + j, a] += inv_mass[lo + j] * f
    return -1


@nb.njit(cache=True)
def projection_step(x, v_off, e_off, rest_len, inv_mass, place, v, a0, h, tol, max_iter, xp, accel):
    """The projection mode's acceleration [m/s^2] (n,) of every free dof: predict
    x + h (v + h a0) for the free vertices, project each rod, and take the acceleration
    that lands there. x, xp (n_vertices, 3): positions now and (scratch) projected.
    Returns the first rod that did not converge, or -1."""
    xp[:] = x
    for vtx in range(x.shape[0]):
        p = place[vtx]
        if p >= 0:
            for a in range(3):
                k = 3 * p + a
                xp[vtx, a] += h * (v[k] + h * a0[k])
    for i in range(len(v_off) - 1):
        v0, v1 = v_off[i], v_off[i + 1]
        if project_rod(xp[v0:v1], inv_mass[v0:v1], rest_len[e_off[i]:e_off[i + 1]], tol, max_iter) < 0:
            return i
    for vtx in range(x.shape[0]):
        p = place[vtx]
        if p >= 0:
            for a in range(3):
                k = 3 * p + a
                accel[k] = ((xp[vtx, a] - x[vtx, a]) / h - v[k]) / h
    return -1
