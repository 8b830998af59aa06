"""Banded linear algebra (derods/_numba/banded.py) and the implicit step matrix (derods/sim/implicit.py),
through their reference forms in tests/oracles.py."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from oracles import (a_matvec, band_cholesky, band_matvec, band_solve, banded_inverse_band, implicit_rhs,
                     implicit_system, inverse_diagonal_terms, k_matvec, restrict_band)


def random_band(rng, n, bw=8):
    a = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - bw), i + 1):
            a[i, j] = a[j, i] = rng.normal()
    a += np.eye(n) * (2 * bw + 5)  # diagonally dominant: positive definite
    ab = np.array([np.concatenate([np.diag(a, -d), np.zeros(d)]) for d in range(bw + 1)])
    return a, ab


def test_band_cholesky_solve_matvec_and_inverse_band():
    rng = np.random.default_rng(0)
    a, ab = random_band(rng, 30)
    lb = band_cholesky(ab)
    np.testing.assert_allclose(lb, scipy.linalg.cholesky_banded(ab, lower=True), rtol=1e-12, atol=1e-14)
    b = rng.normal(size=(30, 2))
    np.testing.assert_allclose(band_solve(lb, b), np.linalg.solve(a, b), rtol=1e-10)
    w = rng.normal(size=30)
    np.testing.assert_allclose(band_matvec(ab, w), a @ w, rtol=1e-12)
    z = np.linalg.inv(a)
    zb = banded_inverse_band(lb)
    for d in range(9):
        np.testing.assert_allclose(zb[d, : 30 - d], np.diag(z, -d), rtol=1e-10, atol=1e-15)


def test_band_cholesky_rejects_indefinite_matrix():
    ab = np.zeros((9, 5))
    ab[0] = [1.0, 1.0, -1.0, 1.0, 1.0]
    try:
        band_cholesky(ab)
    except ValueError as err:
        assert "positive definite" in str(err)
    else:  # pragma: no cover
        raise AssertionError("an indefinite matrix was factored")


def test_restrict_band_is_the_sub_matrix():
    rng = np.random.default_rng(1)
    a, ab = random_band(rng, 24)
    sub = restrict_band(ab, 6, 18)
    a_sub = a[6:18, 6:18]
    for d in range(9):
        np.testing.assert_allclose(sub[d, : 12 - d], np.diag(a_sub, -d))
        np.testing.assert_array_equal(sub[d, 12 - d:], 0.0)


def test_implicit_system_matches_dense_algebra():
    """A = M (1 + h a_m) + (h^2 + h b) (K_band + c g g^T), two rods, one with a rank-one term."""
    rng = np.random.default_rng(2)
    h, am, b = 1e-2, 0.5, 1e-3
    k1, band1 = random_band(rng, 12)
    k2, band2 = random_band(rng, 9)
    g = rng.normal(size=12)
    c = 3.0
    mass = rng.uniform(0.5, 2.0, size=21)
    offsets = np.array([0, 12, 21])
    system = implicit_system(h, offsets, [band1, band2], [(g, c), None], mass, am, b)
    k = np.zeros((21, 21))
    k[:12, :12] = k1 + c * np.outer(g, g)
    k[12:, 12:] = k2
    a = np.diag(mass * (1 + h * am)) + (h * h + h * b) * k
    rhs = rng.normal(size=21)
    np.testing.assert_allclose(system.solve(rhs), np.linalg.solve(a, rhs), rtol=1e-10)
    v = rng.normal(size=21)
    np.testing.assert_allclose(k_matvec(system, v), k @ v, rtol=1e-12)
    np.testing.assert_allclose(a_matvec(system, v), a @ v, rtol=1e-12)
    force = rng.normal(size=21)
    np.testing.assert_allclose(implicit_rhs(system, force, v), force - am * mass * v - (b + h) * k @ v, rtol=1e-12)
    zb, corr = inverse_diagonal_terms(system)
    inv = np.linalg.inv(np.diag(mass * (1 + h * am)) + (h * h + h * b) * np.block(
        [[k1, np.zeros((12, 9))], [np.zeros((9, 12)), k2]]))
    np.testing.assert_allclose(zb[0], np.diag(inv), rtol=1e-10)
    z, w = corr[0]
    np.testing.assert_allclose(np.diag(inv) - w * z**2, np.diag(np.linalg.inv(a)), rtol=1e-10)
