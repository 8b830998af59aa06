"""The linearly implicit (backward Euler) elastic step, solved with banded Cholesky.

One step of size h for the free vertices of all rods at once, written for the
end-of-step acceleration a = dv / h:

    A a = r,    A = M (1 + h a_m) + (h^2 + h b) K,
    r = F - a_m M v - (b + h) K v,

with M the lumped vertex masses, K the positive semi-definite elastic Hessian
(banded per rod, plus a rank-one twist term c g g^T per rod whose frames are
held at both ends), F every force on the vertices (elastic, gravity, user;
contact enters through :mod:`derods.sim.contact`), a_m the mass-proportional
damping rate [1/s] and b the stiffness-proportional damping time [s]
(Rayleigh damping). The banded matrices of all rods are laid end to end
(block diagonal) and factored once; rank-one terms are handled by the
Sherman-Morrison formula. The arithmetic is compiled
(:mod:`derods._numba.implicit`); :class:`ImplicitSystem` holds its arrays.
"""

from __future__ import annotations

import numpy as np

from .._numba import implicit as _k
from ..stencil import XX_BANDWIDTH


class ImplicitSystem:
    """The matrix A of one implicit step for all rods, with its solves.

    Arrays (n dofs, T twist terms): k_band (rows, n), the band of K [N/m]; g (n,), the
    twist directions of all rods laid end to end [1/m]; tw_lo, tw_hi (T,), each twist
    term's dof range; tw_c (T,), its stiffness c [N m]; mass (n,) [kg]. Once the step has
    factored it (:func:`derods._numba.implicit.factor_system`): a_band (A's band), lt (its
    Cholesky factor, column by column, shape (n, rows), see :mod:`derods._numba.banded`),
    z (n,) = B^-1 g per range, den (T,) = 1 + s c g.z.
    """

    def __init__(self, h: float, n: int, mass: np.ndarray, mass_damping: float = 0.0,
                 stiffness_damping: float = 0.0, band_rows: int = XX_BANDWIDTH + 1,
                 tw_lo=(), tw_hi=()):
        self.h = float(h)
        self.n = int(n)
        self.mass = np.ascontiguousarray(mass, dtype=float)
        self.mass_damping = float(mass_damping)
        self.stiffness_damping = float(stiffness_damping)
        self.s = self.h * self.h + self.h * self.stiffness_damping  # weight of K in A
        self.m_coef = 1.0 + self.h * self.mass_damping  # weight of M in A
        self.k_band = np.zeros((band_rows, self.n))
        self.a_band = np.zeros((band_rows, self.n))
        self.lt = np.zeros((self.n, band_rows))
        self.g = np.zeros(self.n)
        self.z = np.zeros(self.n)
        self.tw_lo = np.asarray(tw_lo, dtype=np.int64)
        self.tw_hi = np.asarray(tw_hi, dtype=np.int64)
        self.tw_c = np.zeros(len(self.tw_lo))
        self.den = np.ones(len(self.tw_lo))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs, rhs shape (n,) or (n, m)."""
        cols = np.array(np.atleast_2d(rhs.T), dtype=float)  # (m, n), one solve per row
        for c in cols:
            _k.sm_solve_into(self.lt, self.g, self.tw_lo, self.tw_hi, self.tw_c, self.s, self.z, self.den, c)
        return cols[0] if rhs.ndim == 1 else cols.T
