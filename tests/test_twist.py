"""Quasistatic twist of derods/twist.py (Bergou et al. 2008, section 4.4)."""

from __future__ import annotations

import numpy as np
import pytest

import derods
from derods import frames as fr
from derods import reference, shapes
from derods.twist import TwistBoundary, solve_isotropic, solve_newton

MAT = derods.Material(young=1e7, radius=0.01, poisson=0.5)


@pytest.mark.parametrize("n", [10, 40])
@pytest.mark.parametrize("theta_total", [0.5, 2 * np.pi, -7.0])
def test_clamped_twist_energy_and_linear_theta(n, theta_total):
    """A straight rod whose end edges are turned by Theta relative to each other stores
    beta Theta^2 / (2 L') (continuum: (1/2) int beta tau^2 ds with tau = Theta / L'),
    L' = L - h the distance between the midpoints of the clamped edges, where the
    discrete material frames sit. theta grows linearly along the rod. Exact (round-off)."""
    length = 1.0
    rod = derods.Rod(shapes.straight(length, n), MAT,
                     boundary=TwistBoundary("clamped", 0.3, 0.3 + theta_total))
    state = rod.advance(rod.rest_state(), rod.rest_x)
    l_eff = length - length / n
    np.testing.assert_allclose(rod.energy(state), reference.twist_energy(MAT.beta, theta_total, l_eff), rtol=1e-12)
    s = (np.arange(n) + 0.5) * length / n
    np.testing.assert_allclose(state.theta, 0.3 + theta_total * (s - s[0]) / l_eff, atol=1e-12)


def test_free_rod_carries_no_twist():
    """A free, isotropic, naturally straight rod has no twist term at all; with one end
    held, the twist angles simply follow the reference twist (zero energy)."""
    rod = derods.Rod(shapes.straight(1.0, 20), MAT)
    assert "twist" not in rod.active_terms
    x = shapes.helix(0.1, 0.05, 1.0, 20)
    held = rod.with_boundary(TwistBoundary("free", theta_first=0.4))
    assert "twist" not in held.active_terms
    u = fr.bishop_frames(x, False)
    u = np.cos(np.arange(20))[:, None] * u + np.sin(np.arange(20))[:, None] * np.cross(fr.tangents(x, False), u)
    ref = fr.reference_twist(u, fr.tangents(x, False), False)
    theta, lam = solve_isotropic(ref, rod.vlen, MAT.beta, held.boundary)
    assert theta[0] == 0.4 and lam == 0.0
    np.testing.assert_allclose(theta[1:] - theta[:-1] + ref, 0.0, atol=1e-12)


@pytest.mark.parametrize("total", [1.0, 10.0])
def test_ring_twist_energy(total):
    """A naturally straight ring (a circle of circumference L) with total twist Theta
    stores pi alpha / R (bending, to O(1/n^2)) plus beta Theta^2 / (2 L) (exactly: the
    vertex lengths of a ring add up to 2 L)."""
    n, radius = 60, 0.2
    rod = derods.Rod(shapes.circle(radius, n), MAT, closed=True, natural_curvature=False,
                     boundary=TwistBoundary("ring", total_twist=total))
    assert rod.active_terms == ("stretch", "bend_isotropic", "twist")
    state = rod.advance(rod.rest_state(), rod.rest_x)
    twist = rod.derivatives(state, 0, terms=("twist",)).energy
    np.testing.assert_allclose(twist, reference.twist_energy(MAT.beta, total, rod.length), rtol=1e-12)
    bend = rod.derivatives(state, 0, terms=("bend_isotropic",)).energy
    np.testing.assert_allclose(bend, reference.circle_bending_energy(MAT.alpha, radius),
                               rtol=5 / 6 * (np.pi / n) ** 2 * 1.01)


def arc_state(n=20, theta0=0.1):
    """A planar arc in the xy plane with Bishop directors along +z."""
    s = np.linspace(0, 1.5, n + 1)
    x = np.stack([np.sin(s), 1 - np.cos(s), np.zeros_like(s)], axis=1) * 0.5
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False, u0=np.array([0.0, 0.0, 1.0]))
    return x, derods.RodState(x, u, t, np.full(n, theta0))


def test_newton_turns_anisotropic_rod_onto_weak_axis():
    """An anisotropic rod (B1 = E I1 < B2) bent in the xy plane, its material frame
    started 0.1 rad from the stiff orientation (m1 = z: the curvature binormal along m1,
    all curvature in omega_2, stiffness B2), turns until it bends about its weak axis:
    m2 along +-z, all curvature in omega_1, and the bending energy that of stiffness B1."""
    mat = derods.Material(young=1e7, radius=0.01, radius2=0.004)
    b1, b2 = mat.bend_stiffness
    assert b1 < b2
    x, state = arc_state()
    rod = derods.Rod(shapes.straight(0.75, 20), mat)
    assert rod.active_terms == ("stretch", "bend_material", "twist")
    theta = rod.solve_twist(state)
    m1, m2 = fr.material_frames(state.u, state.t, theta)
    np.testing.assert_allclose(np.abs(m2[:, 2]), 1.0, atol=1e-9)
    solved = derods.RodState(x, state.u, state.t, theta)
    iso = derods.Rod(shapes.straight(0.75, 20), derods.Material(young=1e7, radius=0.01))
    e_iso = iso.derivatives(solved, 0, terms=("bend_isotropic",)).energy
    e_weak = rod.derivatives(solved, 0, terms=("bend_material",)).energy
    np.testing.assert_allclose(e_weak, e_iso * b1 / iso.material.alpha, rtol=1e-9)
    d = rod.derivatives(solved, 1)
    assert np.max(np.abs(d.grad_theta)) < 1e-9 * b1


def test_newton_agrees_with_closed_form_for_isotropic_rod():
    """Newton on the clamped isotropic twist problem lands on the closed form."""
    rng = np.random.default_rng(0)
    x = shapes.helix(0.1, 0.08, 1.2, 25)
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    psi = rng.uniform(-0.3, 0.3, size=25)
    u = np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * np.cross(t, u)
    rod = derods.Rod(shapes.straight(1.0, 25), MAT, boundary=TwistBoundary("clamped", 0.2, 5.0))
    ref = fr.reference_twist(u, t, False)
    closed_form, lam = solve_isotropic(ref, rod.vlen, MAT.beta, rod.boundary)

    def energy(theta, order):
        cfg = derods.Configuration(x, False, u, theta)
        return derods.energy.twist(cfg, MAT.beta, rod.vlen, 0.0, 0.0, order)

    start = np.linspace(0.2, 5.0, 25) + rng.normal(scale=0.1, size=25)
    start[0], start[-1] = 0.2, 5.0
    newton = solve_newton(energy, start, False, rod.boundary)
    np.testing.assert_allclose(newton, closed_form, atol=1e-9)
    # lam is the twisting moment 2 beta d_k / l_k, the same at every joint.
    m = closed_form[1:] - closed_form[:-1] + ref
    np.testing.assert_allclose(2 * MAT.beta * m / rod.vlen, lam, rtol=1e-12)


def test_boundary_errors_name_the_fix():
    with pytest.raises(ValueError, match="theta_first and theta_last"):
        TwistBoundary("clamped", theta_first=0.0)
    with pytest.raises(ValueError, match="kind"):
        TwistBoundary("welded")
    with pytest.raises(ValueError, match="closed rod needs"):
        derods.Rod(shapes.circle(0.1, 10), MAT, closed=True)


def test_reduced_twist_gradient_and_hessian():
    """E*(x) = min_theta E_twist(x, theta) for a clamped rod: its gradient lam * g matches
    central differences, and its Hessian c g g^T + lam sum_k Hess(ref_twist_k) matches
    the symmetric part of the finite-difference Jacobian of that gradient."""
    from fdcheck import GRAD_RTOL, HESS_RTOL, check_gradient, fd_jacobian, rel_error

    from derods import energy as en
    from derods.stencil import scatter_joint_x  # noqa: F401  (documents where g is assembled)

    rng = np.random.default_rng(3)
    nv = 8
    x0 = shapes.helix(0.1, 0.1, 0.8, nv - 1) + rng.normal(scale=0.005, size=(nv, 3))
    t0 = fr.tangents(x0, False)
    u0 = fr.bishop_frames(x0, False)
    rod = derods.Rod(shapes.straight(0.5, nv - 1), MAT, boundary=TwistBoundary("clamped", 0.2, 3.0))

    def reduced(q):
        x = q.reshape(nv, 3)
        cfg = derods.Configuration(x, False, fr.time_parallel_transport(u0, t0, fr.tangents(x, False)))
        return derods.twist.reduce_isotropic(cfg, rod.vlen, MAT.beta, rod.boundary), cfg

    q0 = x0.ravel()
    check_gradient(lambda q: float(reduced(q)[0].energy), lambda q: reduced(q)[0].grad_x.ravel(), q0, GRAD_RTOL)
    red, cfg = reduced(q0)
    h_r = en._ab_to_x_mat(en.reference_twist_hessian(cfg.joint))
    hess = derods.Hessian(nv, False, joint_xx=h_r).dense()[: 3 * nv, : 3 * nv] * red.lam
    hess += red.c * np.outer(red.g.ravel(), red.g.ravel())
    jac = fd_jacobian(lambda q: reduced(q)[0].grad_x.ravel(), q0)
    assert rel_error(hess, 0.5 * (jac + jac.T)) < HESS_RTOL
