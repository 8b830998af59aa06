"""Centerline geometry of derods/geometry.py."""

from __future__ import annotations

import numpy as np
import pytest

from derods import geometry as ge
from fdcheck import fd_jacobian, rel_error


def polyline_with_angles(phis, h=0.3):
    """A planar polyline whose successive edges turn by the given angles."""
    heading = np.concatenate([[0.0], np.cumsum(phis)])
    e = h * np.stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)], axis=1)
    return np.concatenate([[np.zeros(3)], np.cumsum(e, axis=0)])


def test_kb_is_two_tan_half_angle_along_the_binormal():
    phis = np.array([0.0, 0.3, -1.0, 2.5, 3.0])
    x = polyline_with_angles(phis)
    kb = ge.curvature_binormal(x, False)
    np.testing.assert_allclose(kb[:, 2], 2 * np.tan(phis / 2), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(kb[:, :2], 0.0, atol=1e-15)
    np.testing.assert_allclose(ge.turning_angles(x, False), np.abs(phis), atol=1e-12)


def test_voronoi_len_is_twice_the_voronoi_length():
    rest = np.array([1.0, 2.0, 4.0])
    np.testing.assert_allclose(ge.voronoi_len(rest, False), [3.0, 6.0])
    np.testing.assert_allclose(ge.voronoi_len(rest, True), [5.0, 3.0, 6.0])


@pytest.mark.parametrize("closed", [False, True])
def test_joint_indexing(closed):
    nv = 6
    assert ge.n_edges(nv, closed) == (6 if closed else 5)
    assert ge.n_joints(nv, closed) == (6 if closed else 4)
    idx = ge.joint_vertex_index(nv, closed)
    prev, nxt = ge.joint_edge_index(ge.n_edges(nv, closed), closed)
    # The previous edge of a joint ends at the joint vertex; the next edge starts there.
    np.testing.assert_array_equal(prev, idx[:, 0])
    np.testing.assert_array_equal(nxt, idx[:, 1])


def test_kb_jacobians_match_central_differences():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 3))

    def kb(q):
        return ge.JointGeometry(q[:3], q[3:]).kb

    jg = ge.JointGeometry(a, b)
    jac = fd_jacobian(kb, np.concatenate([a, b]))
    assert rel_error(jg.jacobian_ab(), jac) < 1e-8
    w = rng.normal(size=3)
    hess = fd_jacobian(lambda q: ge.JointGeometry(q[:3], q[3:]).jacobian_ab().T @ w, np.concatenate([a, b]))
    assert rel_error(jg.kb_hessian_dot(w), hess) < 1e-7


#: Central differences at h = 1e-6 of a joint's curvature (unit-sized edges) err by about
#: 1e-10 relative (truncation h^2, round-off eps / h): measured at most 2e-10 for the
#: turning angle's Jacobians and second derivatives below, Bergou's kb alike (the bounds of
#: test_kb_jacobians_match_central_differences). 1e-8 leaves a margin of 50 and fails a
#: derivative off by a factor 1 + 1e-8 or more.
JOINT_FD_RTOL = 1e-8
#: Turning angles [rad] that take the series (below 2 atan(ANGLE_SERIES_MAX / 2) = 0.490)
#: and the closed forms of the turning angle's factors, one at the switch, one near a fold.
ANGLES = [1e-3, 0.3, 2 * np.arctan(ge.ANGLE_SERIES_MAX / 2), 1.5, 2.8]


def joint_turning_by(phi: float, rng) -> np.ndarray:
    """Edges (a, b) [m] of lengths 0.7 and 1.3 whose tangents turn by phi [rad] about a
    random axis, concatenated: shape (6,)."""
    ta = rng.normal(size=3)
    ta /= np.linalg.norm(ta)
    axis = np.cross(ta, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    tb = np.cos(phi) * ta + np.sin(phi) * np.cross(axis, ta)
    return np.concatenate([0.7 * ta, 1.3 * tb])


def test_turning_angle_kb_is_the_angle_along_the_binormal():
    """|kb_angle| = phi exactly where |kb| = 2 tan(phi / 2), along the same binormal; as
    phi -> pi it stays finite (pi), where kb grows without bound."""
    phis = np.array([0.0, 1e-4, 0.3, -1.0, 2.5, 3.0, np.pi - 1e-5])
    x = polyline_with_angles(phis)
    jg = ge.JointGeometry(*ge.joint_pairs(ge.edges(x, False), False))
    kb_angle = ge.curvature(jg, "angle").kb
    np.testing.assert_allclose(kb_angle[:, 2], phis, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(kb_angle[:, :2], 0.0, atol=1e-15)
    assert ge.curvature(jg, "tan") is jg
    assert abs(jg.kb[-1, 2]) > 1e5  # Bergou's kb at the same fold: 2 tan(phi / 2) = 4e5


def test_turning_angle_factors_are_smooth_across_the_series_switch():
    """g = 2 atan(x / 2) / x, a = g' / x and b = a' / x: their limits at 0 (1, -1/6, 1/10),
    a and b against central differences of g and a on both sides of ANGLE_SERIES_MAX (steps
    1e-5 x; measured error at most 3e-9, relative), and series and closed forms agreeing at
    the switch (to 1e-13: the closed forms' cancellation there is ~2e-14, measured against
    extended precision)."""
    g0, a0, b0 = ge.turning_angle_factors(np.array(0.0))
    np.testing.assert_allclose([g0, a0, b0], [1.0, -1 / 6, 1 / 10], rtol=1e-15)
    x = np.array([0.1, 0.3, 0.45, 0.55, 1.0, 3.0, 30.0])
    g, a, b = ge.turning_angle_factors(x)
    np.testing.assert_allclose(g, 2 * np.arctan(x / 2) / x, rtol=1e-15)
    h = 1e-5 * x
    g_plus, a_plus, _ = ge.turning_angle_factors(x + h)
    g_minus, a_minus, _ = ge.turning_angle_factors(x - h)
    np.testing.assert_allclose((g_plus - g_minus) / (2 * h) / x, a, rtol=JOINT_FD_RTOL)
    np.testing.assert_allclose((a_plus - a_minus) / (2 * h) / x, b, rtol=JOINT_FD_RTOL)
    edge = ge.ANGLE_SERIES_MAX
    below = ge.turning_angle_factors(np.array(np.nextafter(edge, 0.0)))
    above = ge.turning_angle_factors(np.array(edge))
    np.testing.assert_allclose(below, above, rtol=1e-13)


@pytest.mark.parametrize("phi", ANGLES)
def test_turning_angle_jacobians_match_central_differences(phi):
    """d kb_angle / d(e_a, e_b) = G d kb / d(e_a, e_b) and the second derivatives of
    w . kb_angle (chain rule through G = g I + a kb kb^T) against central differences, with
    series and closed-form factors (tests/test_energy.py checks the energies built on them)."""
    rng = np.random.default_rng(int(1000 * phi))
    q0 = joint_turning_by(phi, rng)
    ta = ge.TurningAngle(ge.JointGeometry(q0[:3], q0[3:]))
    np.testing.assert_allclose(np.linalg.norm(ta.kb), phi, rtol=1e-12)
    jac = fd_jacobian(lambda q: ge.TurningAngle(ge.JointGeometry(q[:3], q[3:])).kb, q0)
    assert rel_error(ta.jacobian_ab(), jac) < JOINT_FD_RTOL
    w = rng.normal(size=3)
    hess = fd_jacobian(lambda q: ge.TurningAngle(ge.JointGeometry(q[:3], q[3:])).jacobian_ab().T @ w, q0)
    assert rel_error(ta.kb_hessian_dot(w), hess) < JOINT_FD_RTOL
    # The same checks tell the measures apart: Bergou's Jacobian is no turning angle's.
    assert rel_error(ta.base.jacobian_ab(), jac) > 1e3 * JOINT_FD_RTOL or phi < 0.01
