"""Frames of derods/frames.py: Bishop transport, reference twist, material frames."""

from __future__ import annotations

import numpy as np
import pytest

from derods import frames as fr
from derods import geometry as ge
from derods import shapes


def wobbly(rng, n=40, closed=False):
    s = np.linspace(0, 2 * np.pi, n, endpoint=not closed)
    x = np.stack([np.cos(s), np.sin(s), 0.4 * np.sin(3 * s)], axis=1)
    return x + rng.normal(scale=0.02, size=x.shape)


@pytest.mark.parametrize("closed", [False, True])
def test_bishop_frames_are_orthonormal(closed):
    x = wobbly(np.random.default_rng(0), 300, closed)
    t = fr.tangents(x, closed)
    u = fr.bishop_frames(x, closed)
    v = np.cross(t, u)
    frame = np.stack([t, u, v], axis=-1)
    gram = np.einsum("nki,nkj->nij", frame, frame)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-12)


def test_transport_maps_tangent_and_fixes_binormal():
    rng = np.random.default_rng(1)
    t1, t2 = rng.normal(size=(2, 50, 3))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 /= np.linalg.norm(t2, axis=1, keepdims=True)
    np.testing.assert_allclose(fr.parallel_transport(t1, t1, t2), t2, atol=1e-13)
    b = np.cross(t1, t2)
    np.testing.assert_allclose(fr.parallel_transport(b, t1, t2), b, atol=1e-13)
    # A rotation: lengths and angles are kept.
    w = rng.normal(size=(50, 3))
    np.testing.assert_allclose(np.linalg.norm(fr.parallel_transport(w, t1, t2), axis=1),
                               np.linalg.norm(w, axis=1), rtol=1e-13)


def test_bishop_frame_is_transported_edge_to_edge():
    x = wobbly(np.random.default_rng(2))
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    np.testing.assert_allclose(fr.parallel_transport(u[:-1], t[:-1], t[1:]), u[1:], atol=1e-12)
    np.testing.assert_allclose(fr.reference_twist(u, t, False), 0.0, atol=1e-12)


@pytest.mark.parametrize("closed", [False, True])
def test_planar_curve_carries_no_twist(closed):
    """In a plane the Bishop director that starts normal to the plane stays normal,
    and a closed planar curve has no holonomy."""
    rng = np.random.default_rng(3)
    s = np.linspace(0, 2 * np.pi, 60, endpoint=not closed)
    x = np.stack([np.cos(s) * (1 + 0.3 * np.cos(3 * s)), np.sin(s), np.zeros_like(s)], axis=1)
    x[:, :2] += rng.normal(scale=0.01, size=(60, 2))
    u = fr.bishop_frames(x, closed, u0=np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(u, np.broadcast_to([0.0, 0.0, 1.0], u.shape), atol=1e-12)
    np.testing.assert_allclose(fr.reference_twist(u, fr.tangents(x, closed), closed), 0.0, atol=1e-12)


@pytest.mark.parametrize("n", [200, 800])
def test_helix_bishop_frenet_angle_advances_by_torsion(n):
    """On a circular helix (radius a, c = pitch / 2 pi) the Frenet frame turns about the
    tangent at the torsion tau = c / (a^2 + c^2) relative to the Bishop frame, so the
    angle between them grows by tau * arc length. The discrete rod follows to O(h^2)."""
    a, pitch, turns = 0.2, 0.15, 2.0
    c = pitch / (2 * np.pi)
    x = shapes.helix(a, pitch, turns, n, start=(a, 0.0, 0.0))  # axis through the origin
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    # Frenet normal at the edge midpoints: points to the helix axis.
    mid = 0.5 * (x[1:] + x[:-1])
    normal = -np.stack([mid[:, 0], mid[:, 1], np.zeros(len(mid))], axis=1)
    normal -= np.einsum("ij,ij->i", normal, t)[:, None] * t
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    angle = np.unwrap(fr.signed_angle(u, normal, t))
    arc = np.cumsum(ge.norm(ge.edges(x, False))) - 0.5 * ge.norm(ge.edges(x, False))
    tau = c / (a**2 + c**2)
    fit = np.polyfit(arc, angle, 1)
    # The angle grows linearly (to round-off) ...
    assert np.ptp(angle - np.polyval(fit, arc)) < 1e-10
    # ... at the torsion, to O(h^2): measured relative error 26 / n^2 (1.0e-2 at n = 50,
    # 6.5e-4 at n = 200, 4.1e-5 at n = 800); tolerance 30 / n^2.
    np.testing.assert_allclose(fit[0], tau, rtol=30 / n**2)


def test_time_parallel_transport_and_reference_twist():
    """Turning every edge's reference director by psi_j changes the reference twist of
    joint k by psi_next - psi_prev; transporting in time keeps frames orthonormal."""
    rng = np.random.default_rng(4)
    x = wobbly(rng, 30)
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    psi = rng.uniform(-0.5, 0.5, size=t.shape[0])
    u2 = np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * np.cross(t, u)
    np.testing.assert_allclose(fr.reference_twist(u2, t, False), psi[1:] - psi[:-1], atol=1e-12)
    x_new = x + rng.normal(scale=0.01, size=x.shape)
    t_new = fr.tangents(x_new, False)
    u_new = fr.time_parallel_transport(u2, t, t_new)
    np.testing.assert_allclose(np.einsum("ij,ij->i", u_new, t_new), 0.0, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(u_new, axis=1), 1.0, rtol=1e-13)


def test_material_frames_and_curvatures():
    rng = np.random.default_rng(5)
    x = wobbly(rng, 20)
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    theta = rng.uniform(-3, 3, size=t.shape[0])
    m1, m2 = fr.material_frames(u, t, theta)
    np.testing.assert_allclose(np.cross(m1, m2), t, atol=1e-13)
    np.testing.assert_allclose(fr.signed_angle(u, m1, t), theta, atol=1e-12)
    kb = ge.curvature_binormal(x, False)
    omega = fr.material_curvatures(kb, m1, m2, False)
    # kb is perpendicular to both edges, so its components in either edge's frame keep its length.
    np.testing.assert_allclose(np.linalg.norm(omega, axis=-1),
                               np.broadcast_to(np.linalg.norm(kb, axis=-1)[:, None], (len(kb), 2)),
                               rtol=1e-12)


def test_bishop_frames_follow_the_numpy_parallel_transport():
    """The compiled loop of bishop_frames against parallel_transport applied edge by edge
    (with the same re-orthonormalization), on a batch of random curves: equal to round-off."""
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.normal(size=(3, 30, 3)), axis=1)
    u = fr.bishop_frames(x, False)
    t = fr.tangents(x, False)
    ref = [u[:, 0]]
    for j in range(1, t.shape[1]):
        v = fr.parallel_transport(ref[-1], t[:, j - 1], t[:, j])
        v = v - np.einsum("bi,bi->b", v, t[:, j])[:, None] * t[:, j]
        ref.append(v / np.linalg.norm(v, axis=1)[:, None])
    np.testing.assert_allclose(u, np.stack(ref, axis=1), atol=1e-13)
