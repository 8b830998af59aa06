"""Closed forms and reference solutions the rods are judged against, each written once.

Cantilevers: the tip deflection under their weight (linear, :func:`cantilever_linear_tip`,
and the elastica, :func:`cantilever_elastica`), bending frequencies (clamped-free
:func:`cantilever_frequency`, with a tip mass :func:`tip_mass_frequency`, free-free
:func:`free_free_frequency`). Twist and rings: the torque of a twisted rod
(:func:`twist_torque`) and its energy (:func:`twist_energy`), the end couple that closes a
straight rod into a circle (:func:`closing_couple`), a circle's bending energy
(:func:`circle_bending_energy`) and Michell's critical twist of a ring
(:func:`michell_critical_twist`). alpha is the bending stiffness E I, beta the twisting
stiffness G J [N m^2] (:class:`derods.Material`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq


def cantilever_linear_tip(q: float, length: float, alpha: float) -> float:
    """Euler-Bernoulli tip deflection q L^4 / (8 alpha) [m] of a cantilever under its weight.

    q: weight per length rho A g [N/m]; length L [m]; alpha: E I [N m^2].
    Valid while q L^3 / alpha << 1.
    """
    return q * length**4 / (8.0 * alpha)


def cantilever_elastica(q: float, length: float, alpha: float, n_nodes: int = 400) -> dict:
    """Inextensible elastica of a horizontal cantilever under its own weight.

    theta(s) is the tangent angle below the horizontal: alpha theta'' = -q (L - s) cos(theta),
    theta(0) = 0, theta'(L) = 0, solved with scipy's solve_bvp
    with continuation in the load. Returns {"tip_drop": [m], "tip_x": [m], "tip_angle": [rad],
    "s": arc length (n_nodes,), "x": (n_nodes,), "z": (n_nodes,) (z negative downwards)}.
    """
    s = np.linspace(0.0, length, n_nodes)
    y = np.zeros((2, n_nodes))
    lam_final = q / alpha
    sol = None
    for frac in np.linspace(0.05, 1.0, 20):
        lam = frac * lam_final

        def rhs(ss, yy, lam=lam):
            return np.vstack([yy[1], -lam * (length - ss) * np.cos(yy[0])])

        def bc(ya, yb):
            return np.array([ya[0], yb[1]])

        sol = solve_bvp(rhs, bc, s, y, tol=1e-10, max_nodes=100000)
        if not sol.success:
            raise RuntimeError(f"elastica solve failed at load fraction {frac:.2f}: {sol.message}")
        y = sol.sol(s)
    theta = sol.sol(s)[0]
    # Integrate the position with the trapezoid rule on a fine grid.
    fine = np.linspace(0.0, length, 20 * n_nodes)
    th = sol.sol(fine)[0]
    ds = fine[1] - fine[0]
    xf = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(th[1:]) + np.cos(th[:-1])) * ds)])
    zf = -np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(th[1:]) + np.sin(th[:-1])) * ds)])
    return {
        "tip_drop": float(-zf[-1]),
        "tip_x": float(xf[-1]),
        "tip_angle": float(theta[-1]),
        "s": s,
        "x": np.interp(s, fine, xf),
        "z": np.interp(s, fine, zf),
    }


#: beta_1 L of a free-free beam (cosh x cos x = 1) and its mode's sigma.
FREE_FREE_BETA_L = 4.7300407449
FREE_FREE_SIGMA = 0.9825022158


def free_free_frequency(alpha: float, line_density: float, length: float) -> float:
    """First bending frequency [Hz] of a free-free beam (Euler-Bernoulli):
    f_1 = (4.7300^2 / (2 pi)) sqrt(alpha / (rho A L^4))."""
    return FREE_FREE_BETA_L**2 / (2.0 * np.pi) * np.sqrt(alpha / (line_density * length**4))


def free_free_mode(s: np.ndarray, length: float) -> np.ndarray:
    """The free-free beam's first mode shape at arc lengths s [m], shape of s, largest
    |value| 1 (at the ends): cosh + cos - sigma (sinh + sin) of beta_1 s."""
    b = FREE_FREE_BETA_L * np.asarray(s, dtype=float) / length
    phi = np.cosh(b) + np.cos(b) - FREE_FREE_SIGMA * (np.sinh(b) + np.sin(b))
    return phi / np.max(np.abs(phi))


#: beta_n L of a clamped-free beam's first modes (1 + cos x cosh x = 0).
CANTILEVER_BETA_L = (1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349)


def cantilever_frequency(alpha: float, line_density: float, length: float, mode: int = 1) -> float:
    """Bending frequency [Hz] of a clamped-free beam (Euler-Bernoulli).

    f_n = (beta_n L)^2 / (2 pi) sqrt(alpha / (rho A L^4)), beta_1 L = 1.8751, ...
    """
    return CANTILEVER_BETA_L[mode - 1] ** 2 / (2.0 * np.pi) * np.sqrt(alpha / (line_density * length**4))


def tip_mass_root(mu: float) -> float:
    """beta L of the first mode of a clamped-free beam with a tip mass mu times its own:
    the smallest root of 1 + cos(bL) cosh(bL) + mu bL (cos(bL) sinh(bL) - sin(bL) cosh(bL))."""
    def f(b):
        return 1.0 + math.cos(b) * math.cosh(b) + mu * b * (math.cos(b) * math.sinh(b) - math.sin(b) * math.cosh(b))

    # the root falls from 1.8751 (mu = 0) towards 0 as (3 / mu)^(1/4); bracket below the first
    hi = CANTILEVER_BETA_L[0] + 1e-9
    lo = min(1.0, 0.5 * (3.0 / max(mu, 1e-12)) ** 0.25)
    while f(lo) * f(hi) > 0:
        lo *= 0.5
    return brentq(f, lo, hi, xtol=1e-14)


def tip_mass_frequency(alpha: float, line_density: float, length: float, mu: float) -> float:
    """First bending frequency [Hz] of a cantilever with a tip mass mu times its own:
    f = (bL)^2 / (2 pi) sqrt(alpha / (rho A L^4)), bL from :func:`tip_mass_root`."""
    b = tip_mass_root(mu)
    return b * b / (2.0 * math.pi) * math.sqrt(alpha / (line_density * length**4))


def twist_torque(beta: float, angle: float, length: float) -> float:
    """The torque [N m] that holds a straight rod of length L [m] twisted by ``angle``
    [rad] between its ends: beta Theta / L (Theta = T L / (G J))."""
    return beta * angle / length


def twist_energy(beta: float, angle: float, length: float) -> float:
    """The elastic energy [J] of a straight rod of length L [m] twisted evenly by
    ``angle`` [rad]: beta Theta^2 / (2 L)."""
    return beta * angle**2 / (2 * length)


def closing_couple(alpha: float, length: float) -> float:
    """The end couple [N m] that bends a straight rod of length L [m] into a closed
    circle (curvature 2 pi / L): 2 pi alpha / L."""
    return 2 * math.pi * alpha / length


def circle_bending_energy(alpha: float, radius: float) -> float:
    """The bending energy [J] of a naturally straight rod bent into a full circle of
    ``radius`` R [m]: (1/2) alpha (1/R)^2 2 pi R = pi alpha / R."""
    return math.pi * alpha / radius


def michell_critical_twist(alpha: float, beta: float) -> float:
    """Michell's critical total twist [rad] of a naturally straight ring: below
    2 pi sqrt(3) alpha / beta it stays planar, above it buckles out of its plane."""
    return 2 * math.pi * math.sqrt(3) * alpha / beta
