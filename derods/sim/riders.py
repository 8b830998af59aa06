"""Bodies that ride on a rod's end edge, turning with its material frame (a cable model's
``B_last`` or ``S_last`` that a sensor, camera or light only reads).

A MuJoCo 3.x cable's end body turns with the cable's end: a ``framequat`` sensor on it, or
a camera looking along it, follows the end's bending and twist. derods' vertex bodies only
translate, so such a body is a mocap body that derods poses at every step, once the step
has the rods' frames and before MuJoCo's forward pass reads it (sensors, cameras):
position [m] on its vertex, orientation R = F F0^T R0, with F the end edge's material frame
(tangent, m1, m2) now, F0 at the start and R0 the body's orientation at the start. Once the
step has moved the vertices, they are posed again (:meth:`Riders.after_step`: on their
vertices, the frame carried to the edge's new tangent by parallel transport), so that what
reads them between steps (``mj_forward``, a viewer) sees them on the rod.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from ..frames import material_frames, parallel_transport


class Rider(NamedTuple):
    """One riding body: its mocap slot, the vertex it sits on and the edge whose material
    frame turns it (indices into the world's flat vertex and edge arrays), and ``start``,
    F0^T R0 (3, 3): its orientation at the start seen from that frame then."""

    mocap: int
    vertex: int
    edge: int
    start: np.ndarray
    #: the edge's two vertices
    ends: tuple


class Riders:
    """A world's riding bodies; ``bool(riders)`` is False when there are none."""

    def __init__(self, riders: list[Rider]):
        self.riders = riders
        self._quat = np.zeros(4)
        self._edges = np.array([r.edge for r in riders], dtype=np.int64)
        self._a, self._b = np.array([r.ends for r in riders], dtype=np.int64).reshape(-1, 2).T

    def __bool__(self) -> bool:
        return bool(self.riders)

    @staticmethod
    def frame(u: np.ndarray, t: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Material frames as rotation matrices, columns (t, m1, m2), shape (k, 3, 3), of
        edges with reference directors u, tangents t (k, 3) and twist angles theta (k,)."""
        m1, m2 = material_frames(u, t, theta)
        return np.stack([t, m1, m2], axis=-1)

    def __call__(self, x: np.ndarray, frames, data: mujoco.MjData) -> None:
        """Pose each riding body at x (n_vertices, 3) [m] and the frames' (u, t, theta) now."""
        e = self._edges
        self._pose(x, self.frame(frames.u[e], frames.t[e], frames.theta[e]), data)

    def after_step(self, x: np.ndarray, frames, data: mujoco.MjData) -> None:
        """Pose them at x (n_vertices, 3) [m] after a step moved the vertices: each edge's
        frame (u, t, theta of the step's start) carried to its tangent at x."""
        e, a, b = self._edges, self._a, self._b
        t = x[b] - x[a]
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        u = parallel_transport(frames.u[e], frames.t[e], t)
        self._pose(x, self.frame(u, t, frames.theta[e]), data)

    def _pose(self, x: np.ndarray, now: np.ndarray, data: mujoco.MjData) -> None:
        for r, f in zip(self.riders, now):
            data.mocap_pos[r.mocap] = x[r.vertex]
            mujoco.mju_mat2Quat(self._quat, (f @ r.start).ravel())
            data.mocap_quat[r.mocap] = self._quat
