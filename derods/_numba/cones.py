"""Elliptic friction cones in the contact solve, compiled: MuJoCo's soft elliptic cone
(its primal cost per contact, three zones) for the Newton solve of
:mod:`derods._numba.contact_newton`.

A contact of dimension dim has a normal row and dim - 1 frictional rows. With jar = J a -
aref over them, MuJoCo maps them into the cone's space, U_0 = mu jar_0, U_j = f_j jar_j
(mu the contact's slope, f_j its coefficients), N = U_0, T = |U_1..|, and the cost is

- top zone (N >= mu T, separating): 0;
- bottom zone (mu N + T <= 0, sticking): sum_j 1/2 D_j jar_j^2, every row a spring;
- middle zone (sliding): 1/2 Dm (N - mu T)^2, Dm = D_0 / (mu^2 (1 + mu^2)),

with D_j = D_0 f_j^2 / mu^2 (MuJoCo's coupling of the rows' regularizers, which makes the
force continuous across the zones). Its Hessian in jar is, in the middle zone,
Dm g g^T + c P with g = grad(N - mu T), c = -Dm mu (N - mu T) / T > 0 and P the
tangential curvature diag(f) (I - u u^T) diag(f), u = U_t / T: a sum of dim - 1
rank-one terms. So each cone enters Newton's linear algebra as dim "virtual rows", V jar
with weights wv (the bottom zone: the rows themselves, weights D; the top zone: nothing),
and every product of the solve (band, far rows, conjugate gradients) works on them
unchanged. The cost is C1 across the zones, so the line search is Newton's on its
increasing derivative, safeguarded by bisection.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np


class Cones(NamedTuple):
    """The elliptic cones among a solve's k rows (c of them): rows (c, 6), each cone's rows
    in the solve's order, normal first, then its dim - 1 frictional rows (-1 past dim);
    dim (c,); mu (c,), MuJoCo's contact slope (friction[0] / sqrt(impratio)); friction
    (c, 5), the frictional rows' coefficients."""

    rows: np.ndarray
    dim: np.ndarray
    mu: np.ndarray
    friction: np.ndarray


@nb.njit(cache=True)
def cone_weights(d, cones):
    """The weights D_j of a cone's frictional rows from its normal row's, D_0 f_j^2 / mu^2
    (MuJoCo's coupling, see the module docstring), written into d (k,) in place."""
    for c in range(len(cones.dim)):
        r0 = cones.rows[c, 0]
        mu = cones.mu[c]
        for j in range(1, cones.dim[c]):
            f = cones.friction[c, j - 1]
            d[cones.rows[c, j]] = d[r0] * f * f / (mu * mu)


@nb.njit(cache=True)
def _split(cones, c, jar, u):
    """Cone c's jar in the cone's space into u (6,); returns (zone, N, T): zone 0 top,
    1 bottom, 2 middle."""
    dim, mu = cones.dim[c], cones.mu[c]
    u[0] = mu * jar[cones.rows[c, 0]]
    tt = 0.0
    for j in range(1, dim):
        u[j] = cones.friction[c, j - 1] * jar[cones.rows[c, j]]
        tt += u[j] * u[j]
    n_, t_ = u[0], math.sqrt(tt)
    if n_ >= mu * t_ or (t_ <= 0.0 and n_ >= 0.0):
        return 0, n_, t_
    if mu * n_ + t_ <= 0.0 or (t_ <= 0.0 and n_ < 0.0):
        return 1, n_, t_
    return 2, n_, t_


@nb.njit(cache=True)
def virtual_rows(cones, jar, d, basis, wv):
    """Each cone's virtual rows at jar (k,): basis (c, 6, 6), row q of cone c's
    coefficients over its rows, and weights wv (c, 6), so that the cone's Hessian in jar is
    sum_q wv_q b_q b_q^T and its gradient sum_q wv_q (b_q . jar) b_q (module docstring).
    Writes basis and wv; returns whether any changed."""
    u = np.zeros(6)
    nb_ = np.zeros((6, 6))
    nw = np.zeros(6)
    v = np.zeros(6)
    changed = False
    for c in range(len(cones.dim)):
        dim, mu = cones.dim[c], cones.mu[c]
        zone, n_, t_ = _split(cones, c, jar, u)
        nb_[:] = 0.0
        nw[:] = 0.0
        if zone == 1:
            for j in range(dim):
                nb_[j, j] = 1.0
                nw[j] = d[cones.rows[c, j]]
        elif zone == 2:
            dm = d[cones.rows[c, 0]] / (mu * mu * (1.0 + mu * mu))
            nb_[0, 0] = mu
            for j in range(1, dim):
                nb_[0, j] = -mu * cones.friction[c, j - 1] * u[j] / t_
            nw[0] = dm
            # The tangential curvature: dim - 2 orthonormal vectors spanning u's complement
            # among the frictional dims (Gram-Schmidt from the unit vectors), in rows
            # 1 .. dim - 2, then scaled by f into jar's space.
            curv = -dm * mu * (n_ - mu * t_) / t_
            q = 1
            for e in range(1, dim):
                if q == dim - 1:
                    break
                v[:] = 0.0
                v[e] = 1.0
                ue = u[e] / t_
                for j in range(1, dim):
                    v[j] -= ue * u[j] / t_
                for p in range(1, q):
                    dp = 0.0
                    for j in range(1, dim):
                        dp += v[j] * nb_[p, j]
                    for j in range(1, dim):
                        v[j] -= dp * nb_[p, j]
                norm = 0.0
                for j in range(1, dim):
                    norm += v[j] * v[j]
                norm = math.sqrt(norm)
                if norm < 1e-6:
                    continue
                for j in range(1, dim):
                    nb_[q, j] = v[j] / norm
                nw[q] = curv
                q += 1
            for p in range(1, q):
                for j in range(1, dim):
                    nb_[p, j] *= cones.friction[c, j - 1]
        for p in range(6):
            if nw[p] != wv[c, p]:
                changed = True
            wv[c, p] = nw[p]
            for j in range(6):
                if nb_[p, j] != basis[c, p, j]:
                    changed = True
                basis[c, p, j] = nb_[p, j]
    return changed


@nb.njit(cache=True)
def write_virtual(rows, vrows, jq, jqv, kb, cones, basis):
    """Cone rows of vrows (:class:`derods._numba.contact_rows.Rows`, a copy of ``rows`` with
    kb banded rows) and of jqv (a copy of their border entries jq (k, m)) as each cone's
    virtual rows (basis, :func:`virtual_rows`) of its rows; a cone's rows share their
    window, or their far columns (:func:`derods._numba.cone_rows.share_patterns`)."""
    for c in range(len(cones.dim)):
        dim = cones.dim[c]
        for p in range(dim):
            rp = cones.rows[c, p]
            for x in range(jq.shape[1]):
                acc = 0.0
                for j in range(dim):
                    acc += basis[c, p, j] * jq[cones.rows[c, j], x]
                jqv[rp, x] = acc
            if rp < kb:
                for x in range(rows.jw.shape[1]):
                    acc = 0.0
                    for j in range(dim):
                        acc += basis[c, p, j] * rows.jw[cones.rows[c, j], x]
                    vrows.jw[rp, x] = acc
            else:
                n_q = rows.fptr[rp - kb + 1] - rows.fptr[rp - kb]
                for x in range(n_q):
                    acc = 0.0
                    for j in range(dim):
                        acc += basis[c, p, j] * rows.fval[rows.fptr[cones.rows[c, j] - kb] + x]
                    vrows.fval[rows.fptr[rp - kb] + x] = acc


@nb.njit(cache=True)
def virtual_jar(cones, basis, wv, jar, w, wjar):
    """The cones' virtual rows' weights into w (k,) and weight times residual into wjar."""
    for c in range(len(cones.dim)):
        dim = cones.dim[c]
        for p in range(dim):
            acc = 0.0
            for j in range(dim):
                acc += basis[c, p, j] * jar[cones.rows[c, j]]
            r = cones.rows[c, p]
            w[r] = wv[c, p]
            wjar[r] = wv[c, p] * acc


@nb.njit(cache=True)
def cone_forces(cones, jar, d, lam):
    """Each cone's row forces -dcost/djar at jar (k,) into lam (k,) (module docstring)."""
    u = np.zeros(6)
    for c in range(len(cones.dim)):
        dim, mu = cones.dim[c], cones.mu[c]
        zone, n_, t_ = _split(cones, c, jar, u)
        for j in range(dim):
            r = cones.rows[c, j]
            if zone == 0:
                lam[r] = 0.0
            elif zone == 1:
                lam[r] = -d[r] * jar[r]
        if zone == 2:
            dm = d[cones.rows[c, 0]] / (mu * mu * (1.0 + mu * mu))
            f0 = -dm * (n_ - mu * t_) * mu
            lam[cones.rows[c, 0]] = f0
            for j in range(1, dim):
                lam[cones.rows[c, j]] = -f0 * u[j] * cones.friction[c, j - 1] / t_


@nb.njit(cache=True)
def _line_terms(jar, jd, d, in_cone, cones, t, x, u, du):
    """The rows' cost's first and second derivatives along jar + t jd (scratch: x (k,),
    u, du (6,))."""
    fp, fpp = 0.0, 0.0
    for i in range(len(jar)):
        if in_cone[i]:
            continue
        r = jar[i] + t * jd[i]
        if r < 0.0:
            fp += d[i] * r * jd[i]
            fpp += d[i] * jd[i] * jd[i]
    for c in range(len(cones.dim)):
        dim, mu = cones.dim[c], cones.mu[c]
        for j in range(dim):
            r = cones.rows[c, j]
            x[r] = jar[r] + t * jd[r]
        zone, n_, t_ = _split(cones, c, x, u)
        if zone == 1:
            for j in range(dim):
                r = cones.rows[c, j]
                fp += d[r] * x[r] * jd[r]
                fpp += d[r] * jd[r] * jd[r]
        elif zone == 2:
            du[0] = mu * jd[cones.rows[c, 0]]
            dt_, dd = 0.0, 0.0
            for j in range(1, dim):
                du[j] = cones.friction[c, j - 1] * jd[cones.rows[c, j]]
                dt_ += u[j] * du[j]
                dd += du[j] * du[j]
            dt_ /= t_
            ddt = (dd - dt_ * dt_) / t_
            dm = d[cones.rows[c, 0]] / (mu * mu * (1.0 + mu * mu))
            g = n_ - mu * t_
            gp = du[0] - mu * dt_
            fp += dm * g * gp
            fpp += dm * (gp * gp - mu * g * ddt)
    return fp, fpp


@nb.njit(cache=True)
def cone_line_search(jar, jd, d, in_cone, cones, d_a, d_g, max_iter=50):
    """Step t minimizing t^2 d_a / 2 + t d_g + the rows' cost along jar + t jd (scalar rows
    one-sided, in_cone's rows by their cones): Newton's method on the increasing derivative
    from t = 1, kept inside a bracket of its sign change by bisection."""
    lo, hi = 0.0, np.inf
    t = 1.0
    x, u, du = np.empty(len(jar)), np.zeros(6), np.zeros(6)
    for _ in range(max_iter):
        fp, fpp = _line_terms(jar, jd, d, in_cone, cones, t, x, u, du)
        fp += t * d_a + d_g
        fpp += d_a
        if fp > 0.0:
            hi = t
        else:
            lo = t
        step = fp / fpp if fpp > 0.0 else 0.0
        nt = t - step
        if not (lo < nt < hi):
            nt = 0.5 * (lo + hi) if hi < np.inf else 2.0 * max(t, 1.0)
        if abs(nt - t) <= 1e-12 * max(1.0, abs(t)):
            return nt
        t = nt
    return t
