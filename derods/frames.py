"""Adapted frames on a discrete rod: Bishop, reference and material frames.

Bergou et al. 2008 (section 4.2 to 4.4) and Bergou et al. 2010 (section 3.1).
Every edge j carries an orthonormal *reference frame* (t^j, u^j, v^j) with
t^j the unit tangent; the *material frame* (t^j, m1^j, m2^j) is the reference
frame turned about t^j by the twist angle theta^j. Two kinds of reference
frame are used:

* space-parallel (Bishop) frames, transported edge to edge along the rod: they
  carry no reference twist (except, on a closed rod, the holonomy at the seam);
* time-parallel frames, transported from the previous time step edge by edge:
  cheap, local, and their *reference twist* (the signed angle between the
  space-parallel transport of u^{prev} and u^{next}) is what enters the twist.

Shapes: ``t`` and ``u`` are (..., n_edges, 3), ``theta`` is (..., n_edges).
"""

from __future__ import annotations

import numpy as np

from .geometry import CHI_MIN, edges, joint_pairs, norm


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def parallel_transport(v: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """Transport vector v from unit tangent t1 to unit tangent t2.

    The rotation about t1 x t2 that takes t1 to t2 (the identity when t1 = t2),
    applied to v: P v = c v + k x v + k (k . v) / (1 + c), k = t1 x t2,
    c = t1 . t2. All arrays shape (..., 3), broadcastable.
    """
    k = np.cross(t1, t2)
    s = t1 + t2
    one_plus_c = np.maximum(0.5 * _dot(s, s), CHI_MIN)
    c = one_plus_c - 1.0
    return c[..., None] * v + np.cross(k, v) + k * (_dot(k, v) / one_plus_c)[..., None]


def signed_angle(u: np.ndarray, v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle [rad] in (-pi, pi] that turns u onto v about ``axis`` (right-handed)."""
    return np.arctan2(_dot(np.cross(u, v), axis), _dot(u, v))


def tangents(x: np.ndarray, closed: bool) -> np.ndarray:
    """Unit edge tangents, shape (..., n_edges, 3). x: vertex positions [m], (..., n_vertices, 3)."""
    e = edges(x, closed)
    return e / norm(e)[..., None]


def perpendicular(t: np.ndarray) -> np.ndarray:
    """Some unit vector perpendicular to each unit vector t, shape (..., 3)."""
    # Cross with the coordinate axis least aligned with t.
    axis = np.zeros_like(t)
    np.put_along_axis(axis, np.argmin(np.abs(t), axis=-1)[..., None], 1.0, axis=-1)
    p = np.cross(t, axis)
    return p / norm(p)[..., None]


def bishop_frames(x: np.ndarray, closed: bool, u0: np.ndarray | None = None) -> np.ndarray:
    """Space-parallel (Bishop) reference directors u^j, shape (..., n_edges, 3).

    u^0 is ``u0`` made perpendicular to t^0 (an arbitrary perpendicular when
    None); each next u^{j+1} is the parallel transport of u^j from t^j to t^{j+1}.
    The frames are orthonormal and twist-free along the rod (Bergou et al.
    2008, section 4.2). The transport along the rod is sequential; it runs
    compiled (:func:`derods._numba.frames.transport_along`), with
    :func:`parallel_transport`'s formula. It sets rods up, not the time step.

    x: vertex positions [m], shape (..., n_vertices, 3).
    u0: first director, shape (..., 3), or None.
    """
    t = tangents(x, closed)
    if u0 is None:
        u = perpendicular(t[..., 0, :])
    else:
        u0 = np.broadcast_to(np.asarray(u0, dtype=float), t[..., 0, :].shape)
        u = u0 - _dot(u0, t[..., 0, :])[..., None] * t[..., 0, :]
        nu = norm(u)
        if np.any(nu < 1e-9):
            raise ValueError("u0 must not be parallel to the first edge tangent; pick another u0")
        u = u / nu[..., None]
    from ._numba.frames import transport_along

    out = np.empty_like(t)
    out[..., 0, :] = u
    flat = out.reshape((-1,) + t.shape[-2:])
    # Re-orthonormalized at every edge against round-off accumulated over long rods.
    transport_along(np.ascontiguousarray(t.reshape(flat.shape)), flat)
    return out


def time_parallel_transport(u_prev: np.ndarray, t_prev: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Carry each edge's reference director from its old tangent to its new one.

    Bergou et al. 2010, section 3.1: the reference frame of edge j at the new
    step is the parallel transport in time of the old one, edge by edge.
    u_prev, t_prev, t: shape (..., n_edges, 3). Returns u, shape (..., n_edges, 3).
    """
    u = parallel_transport(u_prev, t_prev, t)
    u = u - _dot(u, t)[..., None] * t
    return u / norm(u)[..., None]


def reference_twist(u: np.ndarray, t: np.ndarray, closed: bool) -> np.ndarray:
    """Reference twist at every joint [rad], shape (..., n_joints).

    The signed angle about t^{next} from the space-parallel transport of
    u^{prev} (from t^{prev} to t^{next}) to u^{next}. Zero for Bishop frames
    except at the seam of a closed rod, where it is minus the holonomy.
    u, t: reference directors and tangents, shape (..., n_edges, 3).
    """
    u_a, u_b = joint_pairs(u, closed)
    t_a, t_b = joint_pairs(t, closed)
    return signed_angle(parallel_transport(u_a, t_a, t_b), u_b, t_b)


def material_frames(u: np.ndarray, t: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Material directors (m1, m2), each shape (..., n_edges, 3).

    m1 = cos(theta) u + sin(theta) v, m2 = -sin(theta) u + cos(theta) v, v = t x u.
    u, t: shape (..., n_edges, 3); theta: twist angles [rad], shape (..., n_edges).
    """
    v = np.cross(t, u)
    c, s = np.cos(theta)[..., None], np.sin(theta)[..., None]
    return c * u + s * v, c * v - s * u


def material_curvatures(kb: np.ndarray, m1: np.ndarray, m2: np.ndarray, closed: bool) -> np.ndarray:
    """Material curvatures of each joint in the frames of both its edges.

    omega[..., k, s, :] = (kb_k . m2^s, -kb_k . m1^s) for s = 0 (previous edge)
    and s = 1 (next edge) (Bergou et al. 2008, eq. 4), dimensionless.
    kb: shape (..., n_joints, 3); m1, m2: shape (..., n_edges, 3).
    Returns shape (..., n_joints, 2, 2).
    """
    m1a, m1b = joint_pairs(m1, closed)
    m2a, m2b = joint_pairs(m2, closed)
    w_a = np.stack([_dot(kb, m2a), -_dot(kb, m1a)], axis=-1)
    w_b = np.stack([_dot(kb, m2b), -_dot(kb, m1b)], axis=-1)
    return np.stack([w_a, w_b], axis=-2)
