"""Energies of derods/energy.py: exact derivatives, invariances, closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from derods import energy as en
from derods import frames as fr
from derods import geometry as ge
from derods import reference, shapes
from fdcheck import (
    GRAD_RTOL,
    HESS_FROM_ENERGY_RTOL,
    HESS_RTOL,
    check_gradient,
    fd_hessian_from_energy,
    fd_jacobian,
    rel_error,
)


def random_rod(rng, nv: int, closed: bool):
    """A non-degenerate random rod: a wobbly circle or arc, edges of 0.15-0.3 m,
    turning angles well below pi, reference frames turned randomly about the tangents."""
    s = np.linspace(0, 2 * np.pi, nv, endpoint=not closed)
    x = np.stack([np.cos(s), np.sin(s), 0.3 * np.sin(2 * s)], axis=1) * 0.5
    x += rng.normal(scale=0.04, size=x.shape)
    t = fr.tangents(x, closed)
    u = fr.bishop_frames(x, closed)
    ang = rng.uniform(-np.pi, np.pi, size=t.shape[0])
    u = np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * np.cross(t, u)
    theta = rng.uniform(-1, 1, size=t.shape[0])
    return x, t, u, theta


def make_terms(rng, x, closed):
    ne = ge.n_edges(x.shape[0], closed)
    nj = ge.n_joints(x.shape[0], closed)
    rest_len = ge.norm(ge.edges(x, closed)) * rng.uniform(0.9, 1.1, size=ne)
    vlen = ge.voronoi_len(rest_len, closed)
    wbar = rng.normal(scale=0.3, size=(nj, 2, 2))
    mbar = rng.normal(scale=0.3, size=nj)
    offset = np.zeros(nj)
    offset[0] = 0.7 if closed else 0.0
    return {
        "stretch": lambda c, o, psd=False: en.stretch(c, 30.0, rest_len, o, psd),
        "bend_isotropic": lambda c, o, psd=False: en.bend_isotropic(c, 2.0, vlen, o, psd),
        "bend_anisotropic_straight": lambda c, o, psd=False: en.bend_material(
            c, np.array([1.0, 3.0]), vlen, None, o, psd),
        "bend_anisotropic_curved": lambda c, o, psd=False: en.bend_material(
            c, np.array([1.0, 3.0]), vlen, wbar, o, psd),
        "bend_isotropic_curved": lambda c, o, psd=False: en.bend_material(
            c, np.array([2.0, 2.0]), vlen, wbar, o, psd),
        "twist": lambda c, o, psd=False: en.twist(c, 1.5, vlen, mbar, offset, o, psd),
    }


TERMS = ["stretch", "bend_isotropic", "bend_anisotropic_straight", "bend_anisotropic_curved",
         "bend_isotropic_curved", "twist"]


class Problem:
    """E(q), q = (x flattened, theta), with reference frames time-parallel
    transported from the base configuration: the function the derivatives describe."""

    def __init__(self, seed, closed, term, nv=7):
        rng = np.random.default_rng(seed)
        self.closed = closed
        self.x, self.t, self.u, self.theta = random_rod(rng, nv, closed)
        self.f = make_terms(rng, self.x, closed)[term]
        self.nv = nv
        self.q0 = np.concatenate([self.x.ravel(), self.theta])

    def cfg(self, q):
        x = q[: 3 * self.nv].reshape(self.nv, 3)
        t = fr.tangents(x, self.closed)
        return en.Configuration(x, self.closed, fr.time_parallel_transport(self.u, self.t, t),
                                q[3 * self.nv:])

    def energy(self, q):
        return float(self.f(self.cfg(q), 0).energy)

    def grad(self, q):
        d = self.f(self.cfg(q), 1)
        gt = np.zeros(q.size - 3 * self.nv) if d.grad_theta is None else d.grad_theta
        return np.concatenate([d.grad_x.ravel(), gt])

    def hessian(self, q, psd=False):
        return self.f(self.cfg(q), 2, psd).hessian.dense()


CASES = [(seed, closed, term) for closed in (False, True) for term in TERMS for seed in (0, 1)]


@pytest.mark.parametrize("seed,closed,term", CASES)
def test_gradient_matches_central_differences(seed, closed, term):
    p = Problem(seed, closed, term)
    check_gradient(p.energy, p.grad, p.q0, GRAD_RTOL)


@pytest.mark.parametrize("seed,closed,term", CASES)
def test_hessian_matches_central_differences(seed, closed, term):
    """The Hessian is the symmetric part of the Jacobian of the gradient taken with
    frames adapted at every point (the antisymmetric part is transport holonomy),
    and it matches second differences of the energy itself."""
    p = Problem(seed, closed, term)
    h = p.hessian(p.q0)
    jac = fd_jacobian(p.grad, p.q0)
    assert rel_error(h, 0.5 * (jac + jac.T)) < HESS_RTOL
    assert rel_error(h, fd_hessian_from_energy(p.energy, p.q0)) < HESS_FROM_ENERGY_RTOL


def test_checker_catches_a_wrong_gradient():
    """The same checker must fail on a gradient with one wrong factor."""
    p = Problem(0, False, "bend_isotropic")
    check_gradient(p.energy, p.grad, p.q0)
    with pytest.raises(AssertionError, match="central differences"):
        check_gradient(p.energy, lambda q: 1.001 * p.grad(q), p.q0)
    wrong_twist = Problem(0, False, "twist")
    # A reference-twist gradient with the wrong sign, as a sign slip would give.
    with pytest.raises(AssertionError):
        check_gradient(wrong_twist.energy,
                       lambda q: np.concatenate([-wrong_twist.grad(q)[:21], wrong_twist.grad(q)[21:]]),
                       wrong_twist.q0)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("term", TERMS)
def test_psd_hessian_is_positive_semidefinite(closed, term):
    p = Problem(3, closed, term)
    h = p.hessian(p.q0, psd=True)
    ev = np.linalg.eigvalsh(h)
    assert ev.min() >= -1e-10 * np.abs(ev).max()


def random_rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("term", TERMS)
def test_energy_invariant_under_rigid_motion(closed, term):
    p = Problem(5, closed, term)
    rng = np.random.default_rng(9)
    rot, shift = random_rotation(rng), rng.normal(size=3)
    c0 = en.Configuration(p.x, closed, p.u, p.theta)
    c1 = en.Configuration(p.x @ rot.T + shift, closed, p.u @ rot.T, p.theta)
    np.testing.assert_allclose(p.f(c1, 0).energy, p.f(c0, 0).energy, rtol=1e-12)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("term", TERMS)
def test_internal_forces_balance(closed, term):
    """Forces sum to zero; torques about the origin balance the twisting moments:
    sum_i x_i x g_i + sum_j (dE/dtheta^j) t^j = 0 (both vanish for theta at equilibrium)."""
    p = Problem(6, closed, term)
    d = p.f(p.cfg(p.q0), 1)
    g = d.grad_x
    scale = np.abs(g).max() * np.abs(p.x).max()
    np.testing.assert_allclose(g.sum(axis=0), 0.0, atol=1e-12 * np.abs(g).max())
    torque = np.cross(p.x, g).sum(axis=0)
    if d.grad_theta is not None:
        torque += (d.grad_theta[:, None] * p.t).sum(axis=0)
    np.testing.assert_allclose(torque, 0.0, atol=1e-12 * scale)


@pytest.mark.parametrize("n", [50, 100, 200])
def test_circle_bending_energy(n):
    """A naturally straight rod bent into a circle of radius R stores pi alpha / R
    (the continuum (1/2) alpha (1/R)^2 2 pi R: derods.reference.circle_bending_energy). On the inscribed
    regular n-gon |kb| = 2 tan(pi/n) and l = 4 R sin(pi/n), so E / (pi alpha / R) =
    tan(x)^2 / (x sin x) = 1 + (5/6) x^2 + O(x^4), x = pi/n: 0.33 % at n = 50."""
    radius, alpha = 0.3, 2.0
    x = shapes.circle(radius, n)
    rest_len = ge.norm(ge.edges(x, True))
    cfg = en.Configuration(x, True)
    e = float(en.bend_isotropic(cfg, alpha, ge.voronoi_len(rest_len, True), 0).energy)
    exact = reference.circle_bending_energy(alpha, radius)
    rel = abs(e - exact) / exact
    assert rel < 0.01
    np.testing.assert_allclose(rel, 5 / 6 * (np.pi / n) ** 2, rtol=0.01)  # second order


def test_hairpin_fold_is_finite():
    """Edges folded back onto each other: energy and force stay finite and grow."""
    energies = []
    for gap in (1e-2, 1e-4, 1e-6, 1e-9, 0.0):
        phi = np.pi - gap
        x = np.array([[0, 0, 0], [1, 0, 0], [1 + np.cos(phi), np.sin(phi), 0]], dtype=float)
        cfg = en.Configuration(x, False)
        d = en.bend_isotropic(cfg, 1.0, np.array([2.0]), 2)
        assert np.isfinite(d.energy) and np.all(np.isfinite(d.grad_x))
        assert np.all(np.isfinite(d.hessian.joint_xx))
        energies.append(float(d.energy))
    assert energies[0] < energies[1] < energies[2]


def test_banded_hessian_matches_dense_and_solves():
    p = Problem(2, False, "bend_isotropic", nv=12)
    rng = np.random.default_rng(0)
    x, u, th = p.x, p.u, p.theta
    rest_len = ge.norm(ge.edges(x, False))
    vlen = ge.voronoi_len(rest_len, False)
    cfg = en.Configuration(x, False, u, th)
    d = (en.stretch(cfg, 50.0, rest_len, 2, True) + en.bend_isotropic(cfg, 1.0, vlen, 2, True)
         + en.twist(cfg, 1.0, vlen, 0.0, 0.0, 2, True))
    n = 3 * x.shape[0]
    dense = d.hessian.dense()[:n, :n]
    ab = d.hessian.xx_banded()
    for k in range(ab.shape[0]):
        np.testing.assert_allclose(ab[k, : n - k], np.diag(dense, -k), atol=1e-12)
    a = dense + np.eye(n)
    b = rng.normal(size=n)
    ab[0] += 1.0
    np.testing.assert_allclose(scipy.linalg.solveh_banded(ab, b, lower=True), np.linalg.solve(a, b),
                               rtol=1e-10)
    sp = d.hessian.xx_sparse().toarray()
    np.testing.assert_allclose(sp, dense, atol=1e-12)


def test_batch_of_rods_equals_one_by_one():
    """Many rods in one call (leading batch axis) give the same as a loop over rods."""
    rng = np.random.default_rng(4)
    xs = np.stack([random_rod(rng, 9, False)[0] for _ in range(5)])
    rest_len = ge.norm(ge.edges(xs, False))
    vlen = ge.voronoi_len(rest_len, False)
    batch = en.bend_isotropic(en.Configuration(xs, False), 1.3, vlen, 2)
    st = en.stretch(en.Configuration(xs, False), 7.0, rest_len * 1.05, 2)
    for i in range(5):
        one = en.bend_isotropic(en.Configuration(xs[i], False), 1.3, vlen[i], 2)
        np.testing.assert_allclose(batch.energy[i], one.energy, rtol=1e-14)
        np.testing.assert_allclose(batch.grad_x[i], one.grad_x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(batch.hessian.xx_banded()[i], one.hessian.xx_banded(), atol=1e-12)
        s1 = en.stretch(en.Configuration(xs[i], False), 7.0, rest_len[i] * 1.05, 2)
        np.testing.assert_allclose(st.hessian.xx_banded()[i], s1.hessian.xx_banded(), atol=1e-12)
