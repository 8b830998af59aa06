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
    twist directions of all rods laid end to end [1/m]; tw_rod, tw_lo, tw_hi (T,), each
    twist term's rod and dof range; tw_c (T,), its stiffness c [N m]; mass (n,) [kg]. Once
    the step has factored it (:func:`derods._numba.implicit.factor_system`): a_band (A's
    band), lt (its Cholesky factor, column by column, shape (n, rows), see
    :mod:`derods._numba.banded`), z (n,) = B^-1 g per range, den (T,) = 1 + s c g.z, and
    m_coef, s, the weights of M and K it was factored with. ``arrays`` holds them all as
    the compiled kernels take them (:class:`derods._numba.implicit.System`).
    """

    def __init__(self, h: float, n: int, mass: np.ndarray, mass_damping: float = 0.0,
                 stiffness_damping: float = 0.0, band_rows: int = XX_BANDWIDTH + 1,
                 tw_lo=(), tw_hi=(), tw_rod=None):
        self.h = float(h)
        self.n = int(n)
        self.mass_damping = float(mass_damping)
        self.stiffness_damping = float(stiffness_damping)
        tw_lo = np.asarray(tw_lo, dtype=np.int64)
        tw_rod = np.arange(len(tw_lo), dtype=np.int64) if tw_rod is None else np.asarray(tw_rod, dtype=np.int64)
        # The weights of M and K in A, backward Euler's until a step factors it with others.
        weights = np.array([1.0 + self.h * self.mass_damping, self.h * self.h + self.h * self.stiffness_damping])
        self.arrays = _k.System(np.zeros((band_rows, self.n)), np.ascontiguousarray(mass, dtype=float),
                                np.zeros(self.n), tw_rod, tw_lo, np.asarray(tw_hi, dtype=np.int64),
                                np.zeros(len(tw_lo)), np.zeros((band_rows, self.n)), np.zeros((self.n, band_rows)),
                                np.zeros(self.n), np.ones(len(tw_lo)), weights)

    @property
    def k_band(self) -> np.ndarray:
        return self.arrays.k_band

    @k_band.setter
    def k_band(self, band: np.ndarray) -> None:
        self.arrays = self.arrays._replace(k_band=band)

    mass = property(lambda self: self.arrays.mass)
    g = property(lambda self: self.arrays.g)
    tw_rod = property(lambda self: self.arrays.tw_rod)
    tw_lo = property(lambda self: self.arrays.tw_lo)
    tw_hi = property(lambda self: self.arrays.tw_hi)
    tw_c = property(lambda self: self.arrays.tw_c)
    a_band = property(lambda self: self.arrays.a_band)
    lt = property(lambda self: self.arrays.lt)
    z = property(lambda self: self.arrays.z)
    den = property(lambda self: self.arrays.den)

    @property
    def m_coef(self) -> float:
        """The weight of M in A (as last factored)."""
        return float(self.arrays.weights[0])

    @property
    def s(self) -> float:
        """The weight of K in A (as last factored)."""
        return float(self.arrays.weights[1])

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs, rhs shape (n,) or (n, m)."""
        out = np.array(rhs, dtype=float, order="C")
        _k.sm_solve_columns_into(self.arrays, out.reshape(self.n, -1))  # one call for every column
        return out
