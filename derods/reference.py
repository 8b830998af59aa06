"""Closed forms and reference solutions the rods are judged against (REFERENCE.md)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_bvp


def cantilever_linear_tip(q: float, length: float, alpha: float) -> float:
    """Euler-Bernoulli tip deflection q L^4 / (8 alpha) [m] of a cantilever under its weight.

    q: weight per length rho A g [N/m]; length L [m]; alpha: E I [N m^2].
    Valid while q L^3 / alpha << 1.
    """
    return q * length**4 / (8.0 * alpha)


def cantilever_elastica(q: float, length: float, alpha: float, n_nodes: int = 400) -> dict:
    """Inextensible elastica of a horizontal cantilever under its own weight.

    theta(s) is the tangent angle below the horizontal: alpha theta'' = -q (L - s) cos(theta),
    theta(0) = 0, theta'(L) = 0 (REFERENCE.md case 2), solved with scipy's solve_bvp
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


def cantilever_frequency(alpha: float, line_density: float, length: float, mode: int = 1) -> float:
    """Bending frequency [Hz] of a clamped-free beam (REFERENCE.md case 4).

    f_n = (beta_n L)^2 / (2 pi) sqrt(alpha / (rho A L^4)), beta_1 L = 1.8751, ...
    """
    roots = (1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349)
    return roots[mode - 1] ** 2 / (2.0 * np.pi) * np.sqrt(alpha / (line_density * length**4))
