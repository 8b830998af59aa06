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

from .._numba.projection import project_rod

#: Tolerance [relative edge strain] and iteration cap of every projection of a step (the
#: projection mode's, the strain limit's).
PROJECTION_TOL = 1e-10
PROJECTION_MAX_ITER = 50


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
    it = project_rod(x, np.ascontiguousarray(inv_mass, dtype=float), np.ascontiguousarray(rest_len, dtype=float),
                     tol, max_iter)
    if it < 0:
        e = np.diff(x, axis=0)
        strain = np.max(np.abs(np.einsum("ij,ij->i", e, e) / rest_len**2 - 1.0))
        raise RuntimeError(f"fast projection did not converge in {max_iter} iterations (strain {strain:.2e})")
    return x, it
