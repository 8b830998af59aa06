"""Fast projection onto inextensible edges (Goldenthal et al. 2007, Algorithm 1).

The inextensibility method of the DER paper (Bergou et al. 2008, section 6):
after an unconstrained step, positions are projected back onto the manifold
of constant edge lengths, C_j(x) = |e^j|^2 / |ebar^j| - |ebar^j| = 0, by
repeated mass-weighted least-norm corrections

    G dlambda = C,  G = grad C  M^-1  grad C^T,   x <- x - M^-1 grad C^T dlambda,

until every edge strain is below the tolerance. For an open rod G is
tridiagonal (neighbouring edges share a vertex), so each iteration is one
banded solve. derods offers it as ``World(mode="projection")`` beside the
stiff stretching term of the implicit mode, so the two can be weighed.
"""

from __future__ import annotations

import numpy as np

from .._numba.banded import band_cholesky, band_solve


def project(x: np.ndarray, inv_mass: np.ndarray, rest_len: np.ndarray, tol: float = 1e-10,
            max_iter: int = 50) -> tuple[np.ndarray, int]:
    """Project an open rod's vertices onto its rest edge lengths.

    x: vertex positions [m], shape (n_vertices, 3).
    inv_mass: inverse vertex masses [1/kg], shape (n_vertices,); 0 holds a vertex in place.
    rest_len: rest edge lengths [m], shape (n_edges,).
    tol: largest relative edge strain accepted.
    Returns (projected positions [m], iterations). Raises RuntimeError if it does not converge.
    """
    x = np.array(x, dtype=float)
    # Edges between two held vertices cannot move; held vertices sit at the ends, so the
    # edges that can move form one run.
    movable = np.flatnonzero(inv_mass[:-1] + inv_mass[1:] > 0)
    lo, hi = int(movable[0]), int(movable[-1]) + 1
    w0, w1 = inv_mass[lo:hi], inv_mass[lo + 1:hi + 1]
    rest = rest_len[lo:hi]
    for it in range(max_iter + 1):
        e = x[lo + 1:hi + 1] - x[lo:hi]
        sq = np.einsum("ij,ij->i", e, e)
        c = sq / rest - rest
        if np.max(np.abs(c / rest)) < tol:
            return x, it
        g = 2.0 * e / rest[:, None]  # dC_j / dx_{j+1} = g_j, dC_j / dx_j = -g_j
        ab = np.zeros((2, len(c)))
        ab[0] = np.einsum("ij,ij->i", g, g) * (w0 + w1)
        ab[1, :-1] = -np.einsum("ij,ij->i", g[:-1], g[1:]) * w1[:-1]
        dlam = band_solve(band_cholesky(ab), c[:, None])[:, 0]
        f = g * dlam[:, None]
        jt_lam = np.zeros_like(x)  # grad C^T dlambda
        jt_lam[lo + 1:hi + 1] += f
        jt_lam[lo:hi] -= f
        x -= inv_mass[:, None] * jt_lam
    raise RuntimeError(
        f"fast projection did not converge in {max_iter} iterations (strain {np.max(np.abs(c / rest)):.2e})"
    )
