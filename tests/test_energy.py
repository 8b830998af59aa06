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


def random_rod(rng, nv: int, closed: bool, gentle: bool = False):
    """A non-degenerate random rod: a wobbly circle or arc, edges of 0.15-0.3 m,
    turning angles well below pi, reference frames turned randomly about the tangents.
    gentle: an open rod nearly straight instead, edges of ~0.25 m turning by less than
    2 atan(ANGLE_SERIES_MAX / 2) = 0.49 rad (the turning angle's factors then in series)."""
    if gentle:
        x = np.stack([0.25 * np.arange(nv), np.zeros(nv), np.zeros(nv)], axis=1)
        x += rng.normal(scale=0.02, size=x.shape)
    else:
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
    terms = {
        "stretch": lambda c, o, psd=False: en.stretch(c, 30.0, rest_len, o, psd),
        "bend_isotropic": lambda c, o, psd=False, bending="tan": en.bend_isotropic(c, 2.0, vlen, o, psd, bending),
        "bend_anisotropic_straight": lambda c, o, psd=False, bending="tan": en.bend_material(
            c, np.array([1.0, 3.0]), vlen, None, o, psd, bending),
        "bend_anisotropic_curved": lambda c, o, psd=False, bending="tan": en.bend_material(
            c, np.array([1.0, 3.0]), vlen, wbar, o, psd, bending),
        "bend_isotropic_curved": lambda c, o, psd=False, bending="tan": en.bend_material(
            c, np.array([2.0, 2.0]), vlen, wbar, o, psd, bending),
        "twist": lambda c, o, psd=False: en.twist(c, 1.5, vlen, mbar, offset, o, psd),
    }
    # Each bending term again with the turning angle as its measure (same stiffnesses and
    # rest curvatures, natural and twisted frames alike).
    for name in BENDS:
        terms[name + "_angle"] = lambda c, o, psd=False, f=terms[name]: f(c, o, psd, "angle")
    return terms


BENDS = ["bend_isotropic", "bend_anisotropic_straight", "bend_anisotropic_curved", "bend_isotropic_curved"]
ANGLE_TERMS = [name + "_angle" for name in BENDS]
TERMS = ["stretch", *BENDS, "twist", *ANGLE_TERMS]


class Problem:
    """E(q), q = (x flattened, theta), with reference frames time-parallel
    transported from the base configuration: the function the derivatives describe."""

    def __init__(self, seed, closed, term, nv=7, gentle=False):
        rng = np.random.default_rng(seed)
        self.closed = closed
        self.x, self.t, self.u, self.theta = random_rod(rng, nv, closed, gentle)
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


@pytest.mark.parametrize("seed,term", [(seed, term) for term in ANGLE_TERMS for seed in (0, 1)])
def test_turning_angle_in_series_matches_central_differences(seed, term):
    """The turning angle's bending terms on a nearly straight rod, whose joints all take the
    factors' series (below 0.49 rad; the random rods above take their closed forms): gradient
    and Hessian against central differences, with the tolerances of the tests above."""
    p = Problem(seed, False, term, gentle=True)
    assert np.max(ge.turning_angles(p.x, False)) < 2 * np.arctan(ge.ANGLE_SERIES_MAX / 2)
    check_gradient(p.energy, p.grad, p.q0, GRAD_RTOL)
    h = p.hessian(p.q0)
    jac = fd_jacobian(p.grad, p.q0)
    assert rel_error(h, 0.5 * (jac + jac.T)) < HESS_RTOL
    assert rel_error(h, fd_hessian_from_energy(p.energy, p.q0)) < HESS_FROM_ENERGY_RTOL


def test_checker_tells_the_measures_apart():
    """The finite-difference check fails Bergou's gradient on the turning angle's energy (and
    the reverse) on the same rod: the measures differ by about phi^2 / 12 of the curvature,
    12 % at this rod's turns of 1.1-1.3 rad; the other measure's gradient is off by 0.72 and
    0.33 of the largest entry (measured), far above GRAD_RTOL."""
    for angle, tan in (("bend_isotropic_angle", "bend_isotropic"), ("bend_anisotropic_curved",
                                                                     "bend_anisotropic_curved_angle")):
        p, q = Problem(0, False, angle), Problem(0, False, tan)
        check_gradient(p.energy, p.grad, p.q0)
        with pytest.raises(AssertionError, match="central differences"):
            check_gradient(p.energy, q.grad, p.q0)


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


@pytest.mark.parametrize("n", [20, 50, 100])
def test_circle_bending_energy_by_the_turning_angle(n):
    """The turning angle's bending energy of the inscribed regular n-gon: every joint turns by
    2 x, x = pi / n, and l = 4 R sin(x), so E = n alpha (2 x)^2 / l and E / (pi alpha / R) =
    x / sin(x) = 1 + x^2 / 6 + O(x^4), exactly (to round-off): 0.066 % at n = 50, a fifth of
    Bergou's tan^2(x) / (x sin x) (test_circle_bending_energy)."""
    radius, alpha = 0.3, 2.0
    x = shapes.circle(radius, n)
    cfg = en.Configuration(x, True)
    vlen = ge.voronoi_len(ge.norm(ge.edges(x, True)), True)
    e = float(en.bend_isotropic(cfg, alpha, vlen, 0, bending="angle").energy)
    half = np.pi / n
    np.testing.assert_allclose(e / reference.circle_bending_energy(alpha, radius), half / np.sin(half), rtol=1e-12)


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


def test_turning_angle_energy_stays_bounded_at_a_fold():
    """As two edges fold back onto each other (phi -> pi) the turning angle's energy
    alpha phi^2 / l stays below alpha pi^2 / l (here pi^2 / 2 J), where Bergou's
    4 alpha tan^2(phi / 2) / l grows without bound (held finite by the CHI_MIN floor, which
    below a gap of 1.4e-6 rad also clips kb and so the angle read from it); forces and
    Hessian stay finite."""
    for gap in (1e-2, 1e-4, 1e-6, 1e-9):
        phi = np.pi - gap
        x = np.array([[0, 0, 0], [1, 0, 0], [1 + np.cos(phi), np.sin(phi), 0]], dtype=float)
        cfg = en.Configuration(x, False)
        d = en.bend_isotropic(cfg, 1.0, np.array([2.0]), 2, bending="angle")
        assert np.all(np.isfinite(d.grad_x)) and np.all(np.isfinite(d.hessian.joint_xx))
        tan = float(en.bend_isotropic(cfg, 1.0, np.array([2.0]), 0).energy)
        assert float(d.energy) <= np.pi**2 / 2 < tan
        if gap >= 1e-4:
            np.testing.assert_allclose(float(d.energy), phi**2 / 2, rtol=1e-12)


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
