"""The generalized-alpha method's coefficients (Chung and Hulbert 1993), the time
stepping of ``World(mode="alpha")``.

Why this family: backward Euler (the implicit mode) damps a mode of angular frequency
w by (1 + (w h)^2)^(-1/2) per step, so a cantilever swinging at w h = 0.18 keeps 0.55
of its amplitude per period. The trapezoidal rule (Newmark's average acceleration)
damps nothing, but then nothing damps the unresolved stiff stretching modes either,
and a linearly implicit step feeds them every step (an edge turning by phi comes out
stretched by ~phi^2 / 2). Generalized-alpha is the one-parameter family of second
order, unconditionally stable (for linear systems) schemes whose spectral radius falls
from 1 at w h -> 0 to ``rho_inf`` at w h -> infinity, with the least damping of the
resolved modes for a given rho_inf:

    alpha_m = (2 rho_inf - 1) / (rho_inf + 1),   alpha_f = rho_inf / (rho_inf + 1),
    gamma = 1/2 - alpha_m + alpha_f,              beta = (1 - alpha_m + alpha_f)^2 / 4.

Per period of a linear mode at w h = 0.18 (measured by :func:`amplification`), the
amplitude kept is 0.9997 and the period 0.34 % long at rho_inf = 0.6; a mode far
beyond the step's resolution (stretching, w h ~ 1e3) loses 1 - rho_inf of its
amplitude every step. rho_inf = 1 is the trapezoidal rule; rho_inf = 0 damps the
unresolved modes in one step (asymptotic annihilation).

Stability: unconditional for linear systems (any h, any stiffness) when
alpha_m <= alpha_f <= 1/2, which the formulas above give for rho_inf in [0, 1]. The
step is linearized once about the start of the step (as the implicit mode's), so with
large rotations per step the nonlinear stretching terms are handled by the strain
limit (a projection of positions) rather than by the scheme.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

#: The default spectral radius at infinite frequency: damps an unresolved mode by 40 %
#: per step while keeping 0.9997 of a mode at w h = 0.18 per period.
RHO_INF = 0.6


class Coefficients(NamedTuple):
    """The scheme's coefficients (dimensionless; a named tuple, which the compiled step takes
    as it is). Build with :meth:`from_rho_inf`."""

    alpha_m: float
    alpha_f: float
    beta: float
    gamma: float
    rho_inf: float

    @classmethod
    def from_rho_inf(cls, rho_inf: float) -> "Coefficients":
        """Chung and Hulbert's optimal coefficients for the spectral radius rho_inf in
        [0, 1] at infinite frequency."""
        rho_inf = float(rho_inf)
        if not (math.isfinite(rho_inf) and 0.0 <= rho_inf <= 1.0):
            raise ValueError(f"rho_inf must be in [0, 1] (1: trapezoidal rule, no damping; 0: unresolved modes "
                             f"damped in one step), got {rho_inf!r}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        return cls(am, af, 0.25 * (1.0 - am + af) ** 2, 0.5 - am + af, rho_inf)


def amplification(c: Coefficients, wh: float) -> np.ndarray:
    """The 3x3 matrix taking (x, h v, h^2 a) over one step of the undamped oscillator
    x'' = -w^2 x at w h = ``wh``."""
    o2 = wh * wh
    # unknowns (x1, hv1, h^2 a1); rows: Newmark position and velocity, the alpha balance
    lhs = np.array([[1.0, 0.0, -c.beta], [0.0, 1.0, -c.gamma], [o2 * (1.0 - c.alpha_f), 0.0, 1.0 - c.alpha_m]])
    rhs = np.array([[1.0, 1.0, 0.5 - c.beta], [0.0, 1.0, 1.0 - c.gamma], [-o2 * c.alpha_f, 0.0, -c.alpha_m]])
    return np.linalg.solve(lhs, rhs)


def kept_per_period(c: Coefficients, wh: float) -> tuple[float, float]:
    """For a linear mode at w h: the fraction of its amplitude kept per (true) period,
    and its relative period error (> 0: the scheme's period is longer)."""
    eig = np.linalg.eigvals(amplification(c, wh))
    lam = eig[np.argmax(np.abs(eig.imag))]
    steps = 2.0 * math.pi / wh
    return float(abs(lam) ** steps), float(wh / abs(np.angle(lam)) - 1.0)
