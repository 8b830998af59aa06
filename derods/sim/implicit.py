"""The linearly implicit (backward Euler) elastic step, solved with banded Cholesky.

One step of size h for the free vertices of all rods at once, written for the
end-of-step acceleration a = dv / h:

    A a = r,    A = M (1 + h a_m) + (h^2 + h b) K,
    r = F - a_m M v - (b + h) K v,

with M the lumped vertex masses, K the positive semi-definite elastic Hessian
(banded per rod, plus a rank-one twist term c g g^T per rod), F every force on
the vertices (elastic, gravity, user; contact enters through
:mod:`derods.contact`), a_m the mass-proportional damping rate [1/s] and b the
stiffness-proportional damping time [s] (Rayleigh damping). The banded
matrices of all rods are laid end to end (block diagonal) and factored once;
rank-one terms are handled by the Sherman-Morrison formula.
"""

from __future__ import annotations

import numpy as np

from .._numba.banded import band_cholesky, band_matvec, band_solve
from ..stencil import XX_BANDWIDTH


def banded_matvec(ab: np.ndarray, w: np.ndarray) -> np.ndarray:
    """y = H w for symmetric H in lower banded form ab (k + 1, n); w shape (n,)."""
    return band_matvec(ab, np.ascontiguousarray(w, dtype=float))


def restrict_band(ab: np.ndarray, start: int, stop: int) -> np.ndarray:
    """The band of the sub-matrix H[start:stop, start:stop] (dof indices), a copy."""
    sub = ab[:, start:stop].copy()
    n = stop - start
    for d in range(1, sub.shape[0]):
        sub[d, max(n - d, 0):] = 0.0
    return sub


class ImplicitSystem:
    """The matrix A of one implicit step for all rods, with its solves.

    h: time step [s]. offsets: start of each rod's free dofs, shape (n_rods + 1,).
    bands: per rod, the lower band (9, n_rod) of K [N/m].
    rank1: per rod, (g, c) with K += c g g^T [N/m], or None.
    mass: dof masses [kg], shape (n,). mass_damping a_m [1/s]; stiffness_damping b [s].
    """

    def __init__(self, h: float, offsets: np.ndarray, bands: list[np.ndarray],
                 rank1: list[tuple[np.ndarray, float] | None], mass: np.ndarray,
                 mass_damping: float = 0.0, stiffness_damping: float = 0.0):
        self.h = h
        self.offsets = offsets
        self.n = int(offsets[-1])
        self.mass = mass
        self.mass_damping = mass_damping
        self.stiffness_damping = stiffness_damping
        # The widest rod sets the band (rings, in their zig-zag order, are wider).
        rows = max([XX_BANDWIDTH + 1] + [band.shape[0] for band in bands])
        self.k_band = np.zeros((rows, self.n))
        for i, band in enumerate(bands):
            self.k_band[: band.shape[0], offsets[i]:offsets[i + 1]] = band
        # Rank-one terms as full-length vectors (zero outside their rod).
        self.rank1 = []
        for i, r in enumerate(rank1):
            if r is not None and r[1] != 0.0:
                g = np.zeros(self.n)
                g[offsets[i]:offsets[i + 1]] = r[0]
                self.rank1.append((g, float(r[1])))
        self.s = h * h + h * stiffness_damping  # weight of K in A
        self.a_band = self.s * self.k_band
        self.a_band[0] += mass * (1.0 + h * mass_damping)
        self._factor = None

    def k_matvec(self, w: np.ndarray) -> np.ndarray:
        """K w, w shape (n,)."""
        y = banded_matvec(self.k_band, w)
        for g, c in self.rank1:
            y += c * g * (g @ w)
        return y

    def a_matvec(self, w: np.ndarray) -> np.ndarray:
        """A w, w shape (n,)."""
        return self.s * self.k_matvec(w) + self.mass * (1.0 + self.h * self.mass_damping) * w

    def rhs(self, force: np.ndarray, v: np.ndarray) -> np.ndarray:
        """r = F - a_m M v - (b + h) K v [N]."""
        return force - self.mass_damping * self.mass * v - (self.stiffness_damping + self.h) * self.k_matvec(v)

    def factor(self) -> np.ndarray:
        """Lower banded Cholesky factor of the banded part of A (cached)."""
        if self._factor is None:
            self._factor = band_cholesky(self.a_band)
        return self._factor

    def inverse_diagonal_terms(self) -> tuple[np.ndarray, list[tuple[np.ndarray, float]]]:
        """What the entries of A^-1 near the diagonal need.

        Returns (zb, corrections): zb the band (9, n) of B^-1, B the banded part of
        A (Takahashi's recurrence on its factor); corrections a list of (z, w) with
        A^-1 = B^-1 - sum w z z^T (Sherman-Morrison for the rank-one twist terms).
        """
        from .._numba.banded import banded_inverse_band

        zb = banded_inverse_band(self.factor())
        corrections = []
        for g, c in self.rank1:
            z = band_solve(self.factor(), g[:, None])[:, 0]
            sc = self.s * c
            corrections.append((z, sc / (1.0 + sc * (g @ z))))
        return zb, corrections

    def solve(self, rhs: np.ndarray, extra_band: np.ndarray | None = None) -> np.ndarray:
        """(A + E)^-1 rhs, E an optional extra lower band (k, n) with k <= the band of A;
        rhs shape (n,) or (n, m)."""
        if extra_band is None:
            factor = self.factor()
        else:
            ab = self.a_band.copy()
            ab[: extra_band.shape[0]] += extra_band
            factor = band_cholesky(ab)
        b = rhs if rhs.ndim == 2 else rhs[:, None]
        if not self.rank1:
            x = band_solve(factor, np.ascontiguousarray(b))
            return x if rhs.ndim == 2 else x[:, 0]
        gs = np.stack([g for g, _ in self.rank1], axis=1)
        sol = band_solve(factor, np.concatenate([b, gs], axis=1))
        x, z = sol[:, : b.shape[1]], sol[:, b.shape[1]:]
        # The rank-one terms live on disjoint rods, so each is one Sherman-Morrison update:
        # (B + s c g g^T)^-1 r = y - z (s c g.y) / (1 + s c g.z).
        for k, (g, c) in enumerate(self.rank1):
            zk = z[:, k]
            x = x - np.outer(zk, self.s * c * (g @ x)) / (1.0 + self.s * c * (g @ zk))
        return x if rhs.ndim == 2 else x[:, 0]
