"""Central finite-difference checks shared by the tests.

Tolerance: central differences with step h have truncation error O(h^2) and
round-off O(eps / h); at h = 1e-6 (relative to a unit-sized configuration)
both are about 1e-10 relative, so the 1e-6 the DER core issue asks for
leaves four orders of margin. Second differences of the energy itself are
noisier (round-off eps / h^2 = 1e-8 at h = 1e-4) and get 1e-5.
"""

from __future__ import annotations

import numpy as np

GRAD_RTOL = 1e-6
HESS_RTOL = 1e-6
HESS_FROM_ENERGY_RTOL = 1e-5


def rel_error(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| / max |b|: the error relative to the largest entry."""
    scale = np.max(np.abs(b))
    return float(np.max(np.abs(a - b)) / (scale if scale > 0 else 1.0))


def fd_gradient(f, q0: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central-difference gradient of the scalar function f at q0."""
    g = np.empty_like(q0)
    for i in range(q0.size):
        dq = np.zeros_like(q0)
        dq[i] = h
        g[i] = (f(q0 + dq) - f(q0 - dq)) / (2 * h)
    return g


def fd_jacobian(g, q0: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian J[i, j] = d g_i / d q_j of the vector function g."""
    cols = []
    for j in range(q0.size):
        dq = np.zeros_like(q0)
        dq[j] = h
        cols.append((g(q0 + dq) - g(q0 - dq)) / (2 * h))
    return np.stack(cols, axis=1)


def fd_hessian_from_energy(f, q0: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Second central differences of the scalar function f at q0."""
    n = q0.size
    eye = np.eye(n) * h
    out = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            v = (f(q0 + eye[i] + eye[j]) - f(q0 + eye[i] - eye[j])
                 - f(q0 - eye[i] + eye[j]) + f(q0 - eye[i] - eye[j])) / (4 * h * h)
            out[i, j] = out[j, i] = v
    return out


def check_gradient(f, grad, q0: np.ndarray, rtol: float = GRAD_RTOL) -> float:
    """Assert that grad(q0) matches central differences of f; return the relative error."""
    err = rel_error(grad(q0), fd_gradient(f, q0))
    assert err < rtol, f"gradient disagrees with central differences: relative error {err:.3e} >= {rtol:g}"
    return err
