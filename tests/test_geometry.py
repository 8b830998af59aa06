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
