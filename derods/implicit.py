"""The linearly implicit (backward Euler) elastic step, solved with banded Cholesky.

One step of size h for the free vertices of all rods at once:

    (M (1 + h a) + (h^2 + h b) K) dv = h (F - a M v - (b + h) K v),

with M the lumped vertex masses, K the positive semi-definite elastic
Hessian (banded per rod, plus a rank-one twist term c g g^T per rod), F every
force acting on the vertices (elastic, gravity, contact, user), a the
mass-proportional damping rate [1/s] and b the stiffness-proportional damping
time [s] (Rayleigh damping). The banded matrices of all rods are laid end to
end (block diagonal) and factored once; the rank-one terms are handled by the
Sherman-Morrison formula.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .stencil import XX_BANDWIDTH


def banded_matvec(ab: np.ndarray, w: np.ndarray) -> np.ndarray:
    """y = H w for symmetric H in lower banded form ab (k + 1, n); w shape (n,)."""
    y = ab[0] * w
    for d in range(1, ab.shape[0]):
        y[d:] += ab[d, :-d] * w[:-d]
        y[:-d] += ab[d, :-d] * w[d:]
    return y


def restrict_band(ab: np.ndarray, start: int, stop: int) -> np.ndarray:
    """The band of the sub-matrix H[start:stop, start:stop] (dof indices), a copy."""
    sub = ab[:, start:stop].copy()
    n = stop - start
    for d in range(1, sub.shape[0]):
        sub[d, max(n - d, 0):] = 0.0
    return sub


class ImplicitSolver:
    """Solves the implicit step for a list of rods whose free dofs are laid end to end.

    Each call to :meth:`solve` takes the rods' banded Hessians (restricted to
    their free dofs), rank-one twist terms, masses, velocities and forces, and
    returns the velocity change dv for all free dofs.
    """

    def __init__(self, sizes: list[int]):
        self.sizes = list(sizes)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)]).astype(int)
        self.n = int(self.offsets[-1])

    def solve(self, h: float, bands: list[np.ndarray], rank1: list[tuple[np.ndarray, float] | None],
              mass: np.ndarray, v: np.ndarray, force: np.ndarray, mass_damping: float = 0.0,
              stiffness_damping: float = 0.0) -> np.ndarray:
        """Velocity change dv [m/s] of all free dofs, shape (n,).

        h: time step [s]. bands: per rod, the lower band (9, n_rod) of K [N/m].
        rank1: per rod, (g, c) with K += c g g^T, or None. mass: dof masses [kg], (n,).
        v: velocities [m/s], (n,). force: total force F [N], (n,).
        mass_damping: a [1/s]; stiffness_damping: b [s].
        """
        s = h * h + h * stiffness_damping
        ab = np.zeros((XX_BANDWIDTH + 1, self.n))
        kv = np.empty(self.n)
        for i, band in enumerate(bands):
            lo, hi = self.offsets[i], self.offsets[i + 1]
            ab[:, lo:hi] = s * band
            kv[lo:hi] = banded_matvec(band, v[lo:hi])
            if rank1[i] is not None:
                g, c = rank1[i]
                kv[lo:hi] += c * g * (g @ v[lo:hi])
        ab[0] += mass * (1.0 + h * mass_damping)
        rhs = h * (force - mass_damping * mass * v - (stiffness_damping + h) * kv)
        with_rank1 = [i for i, r in enumerate(rank1) if r is not None and r[1] != 0.0]
        cols = [rhs]
        for i in with_rank1:
            col = np.zeros(self.n)
            col[self.offsets[i]:self.offsets[i + 1]] = rank1[i][0]
            cols.append(col)
        factor = scipy.linalg.cholesky_banded(ab, lower=True, check_finite=False)
        sol = scipy.linalg.cho_solve_banded((factor, True), np.stack(cols, axis=1), check_finite=False)
        dv = sol[:, 0].copy()
        for k, i in enumerate(with_rank1):
            lo, hi = self.offsets[i], self.offsets[i + 1]
            g, c = rank1[i]
            z = sol[lo:hi, k + 1]
            # Sherman-Morrison: (A + s c g g^T)^-1 r = y - z (s c g.y) / (1 + s c g.z).
            dv[lo:hi] -= z * (s * c * (g @ dv[lo:hi])) / (1.0 + s * c * (g @ z))
        return dv
