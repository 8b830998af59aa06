"""Quasistatic material frame: solve dE/dtheta = 0 for the free twist angles.

Bergou et al. 2008, section 4.4. Twist waves travel much faster than bending
waves, so the material frame is taken to be at equilibrium at every instant:
given the centerline (and its reference frames), the twist angles theta^j of
the edges minimize the elastic energy subject to the boundary.

Boundaries (:class:`TwistBoundary`):

* ``free``: an open rod with at least one end whose material frame is free.
  An isotropic rod then carries no twist at all (energy zero).
* ``clamped``: an open rod whose first and last edges have given twist angles.
* ``ring``: a closed rod with an imposed total twist Theta, carried as an
  offset at the seam joint 0: m_0 = theta^0 - theta^{n-1} + ref_twist_0 + Theta.

For an isotropic, naturally straight rod the optimum is in closed form: the
excess twist d_k = m_k - mbar_k is spread in proportion to l_k / beta_k, and
the force on the centerline is lambda * sum_k grad(ref_twist_k) with
lambda = 2 beta_k d_k / l_k the same at every joint. Anisotropic or naturally
curved rods need Newton's method on the tridiagonal twist Hessian
(:func:`solve_newton`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg

from .energy import Configuration, Derivatives


@dataclass(frozen=True)
class TwistBoundary:
    """How the material frame is held.

    kind: "free", "clamped" or "ring".
    theta_first, theta_last: twist angles [rad] of the first and last edge of
        a clamped rod, measured from their reference directors; for a "free"
        rod, ``theta_first`` (or ``theta_last``) holds that end if given.
    total_twist: imposed total twist Theta of a ring [rad].
    """

    kind: str = "free"
    theta_first: float | None = None
    theta_last: float | None = None
    total_twist: float = 0.0

    def __post_init__(self):
        from .validation import twist_boundary

        twist_boundary(self)

    def seam_offset(self, n_joints: int) -> np.ndarray | float:
        """Twist offset per joint [rad]: Theta at joint 0 of a ring, else 0."""
        if self.kind != "ring":
            return 0.0
        off = np.zeros(n_joints)
        off[0] = self.total_twist
        return off


def solve_isotropic(ref_twist: np.ndarray, vlen: np.ndarray, beta, boundary: TwistBoundary,
                    rest_twist=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form twist angles of an isotropic, naturally straight rod.

    ref_twist: reference twist of each joint [rad], shape (..., n_joints).
    vlen: vertex lengths l_k [m], shape (..., n_joints).
    beta: twisting stiffness G J [N m^2], scalar or shape (..., n_joints).
    boundary: the :class:`TwistBoundary`.
    rest_twist: mbar [rad], scalar or shape (..., n_joints).
    Returns (theta [rad], shape (..., n_edges); lam [N m], shape (...,)), where
    lam = 2 beta_k (m_k - mbar_k) / l_k is the twisting moment carried by the rod.
    """
    ref_twist = np.asarray(ref_twist, dtype=float)
    shape = ref_twist.shape
    compliance = np.broadcast_to(vlen / beta, shape)  # l_k / beta_k [1/(N m)]
    mbar = np.broadcast_to(np.asarray(rest_twist, dtype=float), shape)
    if boundary.kind == "free":
        d = np.zeros(shape)
        lam = np.zeros(shape[:-1])
    else:
        if boundary.kind == "clamped":
            total = boundary.theta_last - boundary.theta_first
        else:
            total = boundary.total_twist
        excess = total + np.sum(ref_twist - mbar, axis=-1)  # sum_k d_k
        lam = 2.0 * excess / np.sum(compliance, axis=-1)
        d = 0.5 * lam[..., None] * compliance
    # theta^next - theta^prev = d_k + mbar_k - ref_twist_k (- Theta at a ring's seam).
    step = d + mbar - ref_twist
    if boundary.kind == "ring":
        theta0 = np.zeros(shape[:-1] + (1,))
        theta = np.concatenate([theta0, theta0 + np.cumsum(step[..., 1:], axis=-1)], axis=-1)
    elif boundary.kind == "free" and boundary.theta_first is None and boundary.theta_last is not None:
        back = np.cumsum(step[..., ::-1], axis=-1)[..., ::-1]
        theta = np.concatenate([boundary.theta_last - back, np.full(shape[:-1] + (1,), boundary.theta_last)], axis=-1)
    else:
        first = 0.0 if boundary.theta_first is None else boundary.theta_first
        theta = np.concatenate([np.full(shape[:-1] + (1,), first), first + np.cumsum(step, axis=-1)], axis=-1)
    return theta, lam


def free_mask(n_edges: int, boundary: TwistBoundary) -> np.ndarray:
    """Boolean mask of the twist angles the solve may change, shape (n_edges,)."""
    free = np.ones(n_edges, dtype=bool)
    if boundary.kind == "clamped":
        free[0] = free[-1] = False
    elif boundary.kind == "free":
        if boundary.theta_first is not None:
            free[0] = False
        if boundary.theta_last is not None:
            free[-1] = False
    return free


def _theta_hessian(d: Derivatives, n_edges: int, closed: bool) -> np.ndarray:
    """Dense theta-theta Hessian (..., n_edges, n_edges) from the joint blocks."""
    tt = d.hessian.joint_tt
    out = np.zeros(tt.shape[:-3] + (n_edges, n_edges))
    nj = tt.shape[-3]
    k = np.arange(nj)
    a, b = ((k - 1) % n_edges, k) if closed else (k, k + 1)
    np.add.at(out, (..., a, a), tt[..., 0, 0])
    np.add.at(out, (..., b, b), tt[..., 1, 1])
    np.add.at(out, (..., a, b), tt[..., 0, 1])
    np.add.at(out, (..., b, a), tt[..., 1, 0])
    return out


def solve_newton(energy: Callable[[np.ndarray, int], Derivatives], theta0: np.ndarray,
                 closed: bool, boundary: TwistBoundary, tol: float = 1e-10,
                 max_iter: int = 50, slack: float = 1e-14) -> np.ndarray:
    """Minimize the energy over the free twist angles of one rod by damped Newton.

    energy: ``energy(theta, order)`` -> :class:`Derivatives` of every
        theta-dependent term at fixed centerline (order 0 or 2).
    theta0: starting twist angles [rad], shape (n_edges,).
    tol: stop when the largest free-angle gradient entry is below
        ``tol`` times the energy scale [N m].
    slack: the line search accepts a step whose energy rises by at most ``slack``
        times the energy (a sum of squares, resolved by round-off to ~1e-16 of
        itself), so that near the solution full Newton steps are taken instead of
        halved to nothing; a search that finds no step ends the solve.
    Returns the twist angles [rad], shape (n_edges,).

    The theta-theta Hessian is tridiagonal (cyclic on a ring); it is solved
    with a Cholesky factorization of its banded form (a dense solve on a
    ring), with Levenberg-Marquardt damping where it is not positive definite
    and a backtracking line search on the energy.
    """
    theta = np.array(theta0, dtype=float)
    ne = theta.shape[-1]
    free = free_mask(ne, boundary)
    mu = 0.0
    for _ in range(max_iter):
        d = energy(theta, 2)
        g = d.grad_theta[free]
        h = _theta_hessian(d, ne, closed)[np.ix_(free, free)]
        scale = max(float(np.max(np.abs(np.diag(h)))), 1e-300)
        if np.max(np.abs(g)) <= tol * scale:
            break
        step = None
        while step is None:
            hm = h + mu * scale * np.eye(h.shape[0])
            try:
                if closed:
                    scipy.linalg.cho_factor(hm)
                    step = -np.linalg.solve(hm, g)
                else:
                    ab = np.zeros((2, hm.shape[0]))
                    ab[0] = np.diag(hm)
                    ab[1, :-1] = np.diag(hm, -1)
                    step = -scipy.linalg.solveh_banded(ab, g, lower=True)
            except (np.linalg.LinAlgError, scipy.linalg.LinAlgError):
                mu = max(1e-12, 10.0 * mu)
        e0 = d.energy
        gs = float(g @ step)
        s = 1.0
        while True:
            trial = theta.copy()
            trial[free] += s * step
            if energy(trial, 0).energy <= e0 + 1e-4 * s * gs + slack * abs(float(e0)) or s < 1e-8:
                break
            s *= 0.5
        if s < 1e-8:
            break  # no descent left to find
        theta = trial
        mu *= 0.1 if mu > 1e-12 else 0.0
    return theta


@dataclass
class ReducedTwist:
    """The twist term with the twist angles eliminated (isotropic, naturally straight rod).

    E*(x) = min_theta E_twist = (sum_k d_k)^2 / sum_k (l_k / beta_k), a function of the
    centerline through the reference twist alone. Its gradient is lam * g and its
    Hessian c g g^T + lam sum_k Hess(ref_twist_k): a rank-one update of a banded
    matrix, which a banded solve handles with the Sherman-Morrison formula.

    theta: twist angles [rad], shape (..., n_edges).
    lam: twisting moment [N m], shape (...).
    energy: E* [J], shape (...).
    g: sum_k d(ref_twist_k)/dx [1/m], shape (..., n_vertices, 3).
    c: 2 / sum_k (l_k / beta_k) [N m], shape (...); zero when an end is free.
    """

    theta: np.ndarray
    lam: np.ndarray
    energy: np.ndarray
    g: np.ndarray
    c: np.ndarray

    @property
    def grad_x(self) -> np.ndarray:
        """dE*/dx [N], shape (..., n_vertices, 3)."""
        return self.lam[..., None, None] * self.g


def reduce_isotropic(cfg: Configuration, vlen: np.ndarray, beta, boundary: TwistBoundary,
                     rest_twist=0.0) -> ReducedTwist:
    """Solve the quasistatic twist in closed form and return the reduced twist term.

    cfg: current configuration with adapted reference frames ``cfg.u``.
    vlen: vertex lengths l_k [m], shape (..., n_joints).
    beta: twisting stiffness G J [N m^2]; rest_twist: mbar [rad].
    """
    from .energy import _ab_to_x_vec, reference_twist_gradient
    from .stencil import scatter_joint_x

    ref = cfg.reference_twist()
    theta, lam = solve_isotropic(ref, vlen, beta, boundary, rest_twist)
    compliance = np.sum(np.broadcast_to(vlen / beta, ref.shape), axis=-1)
    c = np.zeros(ref.shape[:-1]) if boundary.kind == "free" else 2.0 / compliance
    energy = 0.25 * lam**2 * compliance
    g = scatter_joint_x(_ab_to_x_vec(reference_twist_gradient(cfg.joint)), cfg.n_vertices, cfg.closed)
    return ReducedTwist(theta, lam, energy, g, c)
