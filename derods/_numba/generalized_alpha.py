"""Compiled mirror of :mod:`derods.sim.generalized_alpha`: the unconstrained step of the
generalized-alpha mode, and the position update MuJoCo's Euler step cannot make.

The step solves, for the new algorithmic acceleration a1 (per dof),

    M a_{1-am} + D v_{1-af} + grad + K (1 - af) (x1 - x0) = F,

with a_{1-am} = (1-am) a1 + am a0, v_{1-af} = (1-af) v1 + af v0, D = a_m M + b K
(Rayleigh damping), F gravity plus the user's force, and Newmark's updates

    v1 = v0 + h ((1-gamma) a0 + gamma a1),
    x1 = x0 + h v0 + h^2 ((1/2-beta) a0 + beta a1).

MuJoCo integrates velocities from qacc = (v1 - v0) / h = (1-gamma) a0 + gamma a1, so
the system is written for q = gamma a1 + const: (A / gamma) q = r with

    A = ((1-am) + (1-af) h gamma a_m) M + (1-af) (h^2 beta + h gamma b) K,

the metric in which contacts are then re-solved on qacc.
"""

from __future__ import annotations

import numba as nb

from .implicit import factor_system, k_matvec_into, sm_solve_into, twist_terms


@nb.njit(cache=True)
def alpha_step(system, terms, places, params, scheme, qvel, xfrc_applied, a_prev, offset, v, other, rhs, kv, w,
               qacc):
    """The generalized-alpha step without contact, for all rods: factor A / gamma, solve
    for the unconstrained qacc (n,) [m/s^2] (written into ``qacc``).

    Arguments as :func:`derods._numba.implicit.unconstrained_step`'s, plus scheme (the
    scheme's coefficients, :class:`derods.sim.generalized_alpha.Coefficients`: alpha_m,
    alpha_f, beta, gamma), a_prev (n,) [m/s^2] the last step's algorithmic acceleration,
    offset (n,) [m] where grad and K were evaluated, from the start of the step (0 on the
    first Newton iteration; then the last iterate's x_{1-af} - x0), w (n,) scratch. The
    weights of M and K in the factored matrix are left in ``system.weights``.
    """
    free_vertex, free_body, dofs = places.free_vertex, places.free_body, places.dofs
    mass, grad = system.mass, terms.grad
    h, mass_damping, stiffness_damping, gravity = params
    am, af, beta, gamma = scheme.alpha_m, scheme.alpha_f, scheme.beta, scheme.gamma
    n = len(dofs)
    m_coef = ((1.0 - am) + (1.0 - af) * h * gamma * mass_damping) / gamma
    s = (1.0 - af) * (h * h * beta + h * gamma * stiffness_damping) / gamma
    twist_terms(system, terms, places)
    for p in range(len(free_vertex)):
        b = free_body[p]
        for a in range(3):
            k = 3 * p + a
            v[k] = qvel[dofs[k]]
            other[k] = mass[k] * gravity[a] + xfrc_applied[b, a]
    factor_system(system, m_coef, s)
    # rhs = F - grad - am M a0 - a_m M v_f - K (b v_f + (1-af) dx - offset), with the predictors
    # v_f = (1-af)(v0 + h (1-gamma) a0) + af v0 and dx = h v0 + h^2 (1/2 - beta) a0.
    for p in range(len(free_vertex)):
        vtx = free_vertex[p]
        for a in range(3):
            k = 3 * p + a
            vf = v[k] + (1.0 - af) * h * (1.0 - gamma) * a_prev[k]
            dx = h * v[k] + h * h * (0.5 - beta) * a_prev[k]
            w[k] = stiffness_damping * vf + (1.0 - af) * dx - offset[k]
            rhs[k] = other[k] - grad[vtx, a] - mass[k] * (am * a_prev[k] + mass_damping * vf)
    k_matvec_into(system, w, kv)
    for k in range(n):
        qacc[k] = rhs[k] - kv[k]
    sm_solve_into(system, qacc)
    for k in range(n):
        qacc[k] += (1.0 - gamma) * a_prev[k]


@nb.njit(cache=True)
def finish_step(qacc, a_prev, beta, gamma, h, qpos_adr, qpos):
    """After MuJoCo's Euler step with qacc (n,): carry the algorithmic acceleration
    a1 = (qacc - (1-gamma) a0) / gamma in a_prev, and move the rod dofs' qpos from Euler's
    x0 + h v0 + h^2 qacc to Newmark's x0 + h v0 + h^2 ((1/2-beta) a0 + beta a1).
    qpos_adr (n / 3,): the first qpos of each free vertex (three slides)."""
    for p in range(len(qpos_adr)):
        for a in range(3):
            k = 3 * p + a
            a1 = (qacc[k] - (1.0 - gamma) * a_prev[k]) / gamma
            qpos[qpos_adr[p] + a] -= h * h * (qacc[k] - (0.5 - beta) * a_prev[k] - beta * a1)
            a_prev[k] = a1


@nb.njit(cache=True)
def alpha_point(qacc, a_prev, v, af, beta, gamma, h, offset):
    """offset (n,) [m] <- x_{1-af} - x0 = (1-af) (h v0 + h^2 ((1/2-beta) a0 + beta a1)) for
    the step's qacc (n,), a1 = (qacc - (1-gamma) a0) / gamma. Returns max |offset change|."""
    change = 0.0
    for k in range(len(qacc)):
        a1 = (qacc[k] - (1.0 - gamma) * a_prev[k]) / gamma
        e = (1.0 - af) * (h * v[k] + h * h * ((0.5 - beta) * a_prev[k] + beta * a1))
        change = max(change, abs(e - offset[k]))
        offset[k] = e
    return change
