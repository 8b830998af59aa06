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
from .._numba.banded import inverse_band, matvec_into
from ..stencil import XX_BANDWIDTH


def banded_matvec(ab: np.ndarray, w: np.ndarray) -> np.ndarray:
    """y = H w for symmetric H in lower banded form ab (k + 1, n); w shape (n,)."""
    y = np.empty(ab.shape[1])
    matvec_into(ab, np.ascontiguousarray(w, dtype=float), y)
    return y


def restrict_band(ab: np.ndarray, start: int, stop: int) -> np.ndarray:
    """The band of the sub-matrix H[start:stop, start:stop] (dof indices), a copy."""
    sub = ab[:, start:stop].copy()
    n = stop - start
    for d in range(1, sub.shape[0]):
        sub[d, max(n - d, 0):] = 0.0
    return sub


class ImplicitSystem:
    """The matrix A of one implicit step for all rods, with its solves.

    Arrays (n dofs, T twist terms): k_band (rows, n), the band of K [N/m]; g (n,), the
    twist directions of all rods laid end to end [1/m]; tw_lo, tw_hi (T,), each twist
    term's dof range; tw_c (T,), its stiffness c [N m]; mass (n,) [kg]. After
    :meth:`factor`: a_band (A's band), lt (its Cholesky factor, column by column, shape
    (n, rows), see :mod:`derods._numba.banded`), z (n,) = B^-1 g per range, den (T,) =
    1 + s c g.z.
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

    @classmethod
    def from_blocks(cls, h: float, offsets: np.ndarray, bands: list[np.ndarray],
                    rank1: list[tuple[np.ndarray, float] | None], mass: np.ndarray,
                    mass_damping: float = 0.0, stiffness_damping: float = 0.0) -> "ImplicitSystem":
        """A system from per-rod pieces: offsets (n_rods + 1,) of each rod's dofs; bands,
        each rod's lower band (k_i, n_i) [N/m]; rank1, per rod (g [1/m], c [N m]) or None."""
        rows = max([XX_BANDWIDTH + 1] + [b.shape[0] for b in bands])
        tw = [i for i, r in enumerate(rank1) if r is not None and r[1] != 0.0]
        sys_ = cls(h, int(offsets[-1]), mass, mass_damping, stiffness_damping, rows,
                   [offsets[i] for i in tw], [offsets[i + 1] for i in tw])
        for i, band in enumerate(bands):
            sys_.k_band[: band.shape[0], offsets[i]:offsets[i + 1]] = band
        for k, i in enumerate(tw):
            sys_.g[offsets[i]:offsets[i + 1]] = rank1[i][0]
            sys_.tw_c[k] = rank1[i][1]
        sys_.factor()
        return sys_

    def factor(self) -> None:
        """Assemble A's band, factor it, and prepare the Sherman-Morrison terms."""
        _k.factor_system(self.k_band, self.mass, self.m_coef, self.s, self.a_band, self.lt, self.g,
                         self.tw_lo, self.tw_hi, self.tw_c, self.z, self.den)

    def k_matvec(self, w: np.ndarray) -> np.ndarray:
        """K w, w shape (n,)."""
        y = np.empty(self.n)
        _k.k_matvec_into(self.k_band, self.g, self.tw_lo, self.tw_hi, self.tw_c,
                         np.ascontiguousarray(w, dtype=float), y)
        return y

    def a_matvec(self, w: np.ndarray) -> np.ndarray:
        """A w, w shape (n,)."""
        return self.s * self.k_matvec(w) + self.mass * self.m_coef * w

    def rhs(self, force: np.ndarray, v: np.ndarray) -> np.ndarray:
        """r = F - a_m M v - (b + h) K v [N]."""
        return force - self.mass_damping * self.mass * v - (self.stiffness_damping + self.h) * self.k_matvec(v)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^-1 rhs, rhs shape (n,) or (n, m)."""
        cols = np.array(np.atleast_2d(rhs.T), dtype=float)  # (m, n), one solve per row
        for c in cols:
            _k.sm_solve_into(self.lt, self.g, self.tw_lo, self.tw_hi, self.tw_c, self.s, self.z, self.den, c)
        return cols[0] if rhs.ndim == 1 else cols.T

    def inverse_diagonal_terms(self) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
        """What the entries of A^-1 near the diagonal need.

        Returns (zb, corrections): zb the band of B^-1, B the banded part of A
        (Takahashi's recurrence on its factor); corrections a list of (z, w) with
        A^-1 = B^-1 - sum w z z^T (Sherman-Morrison for the rank-one twist terms).
        """
        corrections = []
        for i in range(len(self.tw_lo)):
            z = np.zeros(self.n)
            lo, hi = self.tw_lo[i], self.tw_hi[i]
            z[lo:hi] = self.z[lo:hi]
            corrections.append((z, self.s * self.tw_c[i] / self.den[i]))
        return inverse_band(self.lt, self.lt.shape[1]), corrections
