"""One step's terms for a set of rods (derods/step.py, derods/_numba/step.py) against the
numpy path of Rod.step_terms, which tests/test_energy.py holds to finite differences."""

from __future__ import annotations

import numpy as np
import pytest

import derods
from derods import shapes
from derods import step as step_module
from derods.twist import TwistBoundary

MAT = derods.Material(young=1e8, radius=0.01)
# The kernel evaluates the same formulas in another order: agreement to round-off.
RTOL = 1e-12


def bent(rod, rng, amp=0.1):
    s = np.linspace(0, 1, rod.n_vertices)
    x = rod.rest_x + amp * np.stack([0 * s, np.sin(3 * s), 1 - np.cos(2 * s)], axis=-1)
    return x + rng.normal(scale=0.01, size=x.shape)


def count_kernel_calls(monkeypatch) -> list:
    """A list that grows by one at every call of the compiled step's entry point
    (derods.step.evaluate), which Rod.step_terms takes on its kernel path only."""
    calls = []
    evaluate = step_module.evaluate

    def counted(*args, **kwargs):
        calls.append(1)
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(step_module, "evaluate", counted)
    return calls


BOUNDARIES = [
    TwistBoundary(),
    TwistBoundary("free", theta_last=0.3),
    TwistBoundary("free", theta_first=-0.2),
    TwistBoundary("clamped", 0.1, 4.0),
]


@pytest.mark.parametrize("bending", ["tan", "angle"])
@pytest.mark.parametrize("boundary", BOUNDARIES)
@pytest.mark.parametrize("batch", [(), (4,), (2, 3)])
def test_kernel_matches_numpy(boundary, batch, bending, monkeypatch):
    """Isotropic, naturally straight rods (the twist in closed form), with either measure of
    bending: the kernel's numbers are the numpy path's to round-off."""
    rng = np.random.default_rng(len(batch))
    rest = shapes.straight(1.0, 15)
    rest = np.broadcast_to(rest, batch + rest.shape).copy()
    rod = derods.Rod(rest, MAT, boundary=boundary, rest_twist=0.05, bending=bending)
    state = rod.rest_state()
    x = bent(rod, rng)
    calls = count_kernel_calls(monkeypatch)
    a = rod.step_terms(state, x, use_kernel=True)
    b = rod.step_terms(state, x, use_kernel=False)
    assert len(calls) == 1  # the compiled step gave a, the numpy path b
    for name in ("energy", "grad_x", "hessian_banded"):
        va, vb = getattr(a, name), getattr(b, name)
        assert va.shape == vb.shape
        np.testing.assert_allclose(va, vb, rtol=RTOL, atol=RTOL * np.abs(vb).max(), err_msg=name)
    for name in ("u", "t", "theta"):
        np.testing.assert_allclose(getattr(a.state, name), getattr(b.state, name), atol=1e-12, err_msg=name)
    for name in ("theta", "lam", "energy", "g", "c"):
        np.testing.assert_allclose(getattr(a.twist, name), getattr(b.twist, name),
                                   rtol=RTOL, atol=1e-12, err_msg=name)
    np.testing.assert_allclose(a.grad_theta, b.grad_theta, rtol=RTOL, atol=1e-12)


def test_kernel_steps_chain_like_advance():
    """Stepping twice through the kernel carries the frames like Rod.advance."""
    rng = np.random.default_rng(7)
    rod = derods.Rod(shapes.straight(1.0, 12), MAT, boundary=TwistBoundary("clamped", 0.0, 2.0))
    s_k = s_n = rod.rest_state()
    for amp in (0.05, 0.1, 0.15):
        x = bent(rod, rng, amp)
        s_k = rod.step_terms(s_k, x, use_kernel=True).state
        s_n = rod.advance(s_n, x)
    np.testing.assert_allclose(s_k.u, s_n.u, atol=1e-12)
    np.testing.assert_allclose(s_k.theta, s_n.theta, atol=1e-12)


@pytest.mark.parametrize("bending", ["tan", "angle"])
@pytest.mark.parametrize("total_twist", [0.0, 7.0])
@pytest.mark.parametrize("batch", [(), (3,)])
def test_kernel_matches_numpy_on_rings(total_twist, batch, bending, monkeypatch):
    """Rings: wrap-around stencils, the twist seam, and the band in ring order."""
    rng = np.random.default_rng(11)
    rest = shapes.circle(0.2, 14)
    rest = np.broadcast_to(rest, batch + rest.shape).copy()
    ring = derods.Rod(rest, MAT, closed=True, natural_curvature=False,
                      boundary=TwistBoundary("ring", total_twist=total_twist), bending=bending)
    state = ring.rest_state()
    x = rest + rng.normal(scale=0.01, size=rest.shape)
    calls = count_kernel_calls(monkeypatch)
    a = ring.step_terms(state, x, use_kernel=True)
    b = ring.step_terms(state, x, use_kernel=False)
    assert len(calls) == 1  # the compiled step gave a, the numpy path b
    for name in ("energy", "grad_x"):
        va, vb = getattr(a, name), getattr(b, name)
        np.testing.assert_allclose(va, vb, rtol=RTOL, atol=RTOL * np.abs(vb).max(), err_msg=name)
    np.testing.assert_allclose(a.hessian_banded, b.hessian_banded, rtol=RTOL,
                               atol=RTOL * np.abs(b.hessian_banded).max())
    for name in ("u", "t", "theta"):
        np.testing.assert_allclose(getattr(a.state, name), getattr(b.state, name), atol=1e-12, err_msg=name)
    for name in ("theta", "lam", "energy", "g", "c"):
        np.testing.assert_allclose(getattr(a.twist, name), getattr(b.twist, name),
                                   rtol=RTOL, atol=1e-12, err_msg=name)
    if total_twist:
        assert np.all(a.twist.lam != 0)  # the seam's twist is carried


MATERIAL_CASES = [
    # (rest shape, closed, material, boundary): anisotropic and naturally curved rods.
    ("straight", False, derods.Material(young=1e8, radius=0.01, radius2=0.004), TwistBoundary()),
    ("straight", False, derods.Material(young=1e8, radius=0.01, radius2=0.004), TwistBoundary("free", theta_first=0.2)),
    ("straight", False, derods.Material(young=1e8, radius=0.01, radius2=0.004), TwistBoundary("clamped", 0.1, 2.0)),
    ("helix", False, MAT, TwistBoundary("free", theta_last=-0.3)),
    ("helix", False, derods.Material(young=1e8, radius=0.01, radius2=0.006), TwistBoundary("clamped", 0.0, 1.0)),
    ("circle", True, MAT, TwistBoundary("ring", total_twist=3.0)),
    ("circle", True, derods.Material(young=1e8, radius=0.01, radius2=0.005), TwistBoundary("ring", total_twist=0.0)),
]


@pytest.mark.parametrize("bending", ["tan", "angle"])
@pytest.mark.parametrize("shape,closed,mat,boundary", MATERIAL_CASES)
def test_kernel_matches_numpy_on_anisotropic_and_curved_rods(shape, closed, mat, boundary, bending, monkeypatch):
    """The compiled Newton twist solve and material-curvature bending against the numpy
    path (bend_material + twist, derods.twist.solve_newton). Both stop Newton when the
    free twist gradient is below 1e-10 of the theta Hessian's scale, so the angles agree
    to that tolerance, not to round-off: rtol = 1e-8 on every quantity (measured
    agreement: better than 1e-11), with either measure of bending."""
    rng = np.random.default_rng(3)
    rest = {"straight": shapes.straight(1.0, 14), "helix": shapes.helix(0.1, 0.06, 1.5, 16),
            "circle": shapes.circle(0.2, 14)}[shape]
    rod = derods.Rod(rest, mat, closed=closed, boundary=boundary, bending=bending)
    assert not rod.has_closed_form_twist
    state = rod.advance(rod.rest_state(), rod.rest_x)
    x = rest + rng.normal(scale=0.01, size=rest.shape)
    calls = count_kernel_calls(monkeypatch)
    a = rod.step_terms(state, x, use_kernel=True)
    b = rod.step_terms(state, x, use_kernel=False)
    assert len(calls) == 1  # the compiled step gave a, the numpy path b
    rtol = 1e-8
    for name in ("energy", "grad_x", "hessian_banded", "grad_theta"):
        va, vb = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        assert va.shape == vb.shape, name
        np.testing.assert_allclose(va, vb, rtol=rtol, atol=rtol * max(np.abs(vb).max(), 1.0), err_msg=name)
    np.testing.assert_allclose(a.state.theta, b.state.theta, atol=1e-8)
    np.testing.assert_allclose(a.state.u, b.state.u, atol=1e-12)
    assert np.all(a.twist.c == 0) and np.all(b.twist.c == 0)  # no rank-one term: Newton's twist


@pytest.mark.parametrize("closed", [False, True])
def test_kernel_bends_by_the_turning_angle(closed):
    """The compiled step of a rod with bending="angle" stores alpha phi_k^2 / l_k at each joint
    (phi_k its turning angle, read with atan2 here, independently of kb) beside the stretch
    and the twist, to round-off; Bergou's measure stores 4 alpha tan^2(phi_k / 2) / l_k, more
    by about phi^2 / 6 (4 % on the open rod, 9 % on the ring, turns of 0.07-0.84 rad). A soft
    stretch (1 N) keeps the stretch energy from burying the bending's digits."""
    rng = np.random.default_rng(5)
    rest = shapes.circle(0.2, 16) if closed else shapes.straight(1.0, 12)
    bd = TwistBoundary("ring") if closed else TwistBoundary()
    x = (rest + rng.normal(scale=0.01, size=rest.shape) if closed
         else bent(derods.Rod(rest, MAT), rng, 0.3))
    ta, tb = derods.geometry.joint_pairs(derods.frames.tangents(x, closed), closed)
    phi = np.arctan2(np.linalg.norm(np.cross(ta, tb), axis=-1), np.sum(ta * tb, axis=-1))
    bend = {}
    for bending in ("tan", "angle"):
        rod = derods.Rod(rest, MAT, closed=closed, natural_curvature=False, boundary=bd, stretch_stiffness=1.0,
                         bending=bending)
        a = rod.step_terms(rod.rest_state(), x, use_kernel=True)
        bend[bending] = a.energy - a.twist.energy - rod.derivatives(a.state, 0, terms=("stretch",)).energy
    np.testing.assert_allclose(bend["angle"], np.sum(MAT.alpha * phi**2 / rod.vlen), rtol=RTOL)
    np.testing.assert_allclose(bend["tan"], np.sum(4 * MAT.alpha * np.tan(phi / 2)**2 / rod.vlen), rtol=RTOL)
    assert bend["tan"] > 1.03 * bend["angle"]
