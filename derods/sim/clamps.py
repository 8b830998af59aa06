"""Pins and clamps: how held ends shape the twist, follow their bodies, and push back.

A pin holds an end vertex; a clamp holds the end edge (two vertices) and the
material frame on it. Held by the world they stay put; held by a MuJoCo body
(``start_body=`` / ``end_body=``) they ride on it: the held vertices are
children of the body, a clamp's material director turns with it (its angle
from the transported reference frame, unwrapped over many turns, becomes the
twist boundary of every step, see :func:`derods._numba.step.rods_step`), and
the body feels the rod's force on the held vertices and, through a clamp, the
twisting moment the rod resists with (:class:`Reactions`; explicit: applied
with the forces of the step that computed them).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .._numba.coupling import holder_wrench
from ..step import EndBodies
from ..twist import TwistBoundary
from .layout import Layout, RodEntry


def twist_boundary(rod, start: str, end: str, name: str) -> TwistBoundary:
    """The twist boundary an open rod's ends impose: both clamped keeps the rod's own
    clamped boundary (or holds both frames at 0); one clamp holds that end's frame."""
    bd = rod.boundary
    if start == "clamp" and end == "clamp":
        return bd if bd.kind == "clamped" else TwistBoundary("clamped", 0.0, 0.0)
    if bd.kind == "clamped":
        raise ValueError(
            f"rod '{name}': TwistBoundary('clamped') needs start='clamp' and end='clamp', "
            f"got start={start!r}, end={end!r}"
        )
    if start == "clamp":
        return TwistBoundary("free", theta_first=bd.theta_first or 0.0)
    if end == "clamp":
        return TwistBoundary("free", theta_last=bd.theta_last or 0.0)
    return TwistBoundary("free")


def end_bodies(model: mujoco.MjModel, data: mujoco.MjData, entries: list[RodEntry], u: np.ndarray,
               t: np.ndarray, theta: np.ndarray, e_off: np.ndarray, theta_end: np.ndarray) -> EndBodies:
    """Clamps held by moving bodies, at the start: each clamp's material director in its
    body's frame, and the unwrapped angles (theta_end (n_rods, 2), set here) it starts from.

    u, t, theta: the rods' initial reference directors and tangents (n_edges, 3) and twist
    angles [rad], flat with edge offsets e_off. The body carries the clamped edge's
    material director, u turned by theta about t: an imposed end twist that is not a
    multiple of 2 pi stays what it is (carrying u instead snapped it to one).
    """
    ends = EndBodies.none(len(entries))
    for i, e in enumerate(entries):
        for k, key in enumerate(("start", "end")):
            kind = e.start if key == "start" else e.end
            if kind != "clamp" or e.holder(key) is None:
                continue
            b = model.body(e.holder(key)).id
            edge = int(e_off[i]) if key == "start" else int(e_off[i + 1]) - 1
            ends.body[i, k] = b
            m1 = math.cos(theta[edge]) * u[edge] + math.sin(theta[edge]) * np.cross(t[edge], u[edge])
            ends.director[i, k] = data.xmat[b].reshape(3, 3).T @ m1
            theta_end[i, k] = theta[edge]
    return ends


class Reactions:
    """The rods' force and twisting moment on the bodies that hold their ends.

    Built once from the layout: every vertex held by a body, grouped by body ("slot"),
    and every clamp on a body with its edge. Each step, :meth:`apply` adds the total
    wrench per body to ``qfrc_applied`` through ``mj_applyFT`` (about the body's
    position), replacing what it added the step before, so forces the user puts there
    stay.
    """

    def __init__(self, model: mujoco.MjModel, layout: Layout, entries: list[RodEntry], e_off: np.ndarray):
        held_vertex, held_slot, clamp_slot, clamp_edge, clamp_rod, clamp_sign = [], [], [], [], [], []
        bodies: list[int] = []
        for i, e in enumerate(entries):
            for key in ("start", "end"):
                name = e.holder(key)
                if name is None:
                    continue
                b = model.body(name).id
                if b not in bodies:
                    bodies.append(b)
                s = bodies.index(b)
                for v in e.held(key):
                    held_vertex.append(layout.v_off[i] + v)
                    held_slot.append(s)
                if (e.start if key == "start" else e.end) == "clamp":
                    clamp_slot.append(s)
                    clamp_edge.append(int(e_off[i]) if key == "start" else int(e_off[i + 1]) - 1)
                    clamp_rod.append(i)
                    clamp_sign.append(0 if key == "start" else 1)
        self.bodies = np.array(bodies, dtype=np.int64)
        self.held_vertex = np.array(held_vertex, dtype=np.int64)
        self.held_slot = np.array(held_slot, dtype=np.int64)
        self.clamp_slot = np.array(clamp_slot, dtype=np.int64)
        self.clamp_edge = np.array(clamp_edge, dtype=np.int64)
        self.clamp_rod = np.array(clamp_rod, dtype=np.int64)
        self.clamp_end = np.array(clamp_sign, dtype=np.int64)
        self.force = np.zeros((len(bodies), 3))
        self.torque = np.zeros((len(bodies), 3))
        self._applied = np.zeros(model.nv)
        self._qfrc = np.zeros(model.nv)

    def __bool__(self) -> bool:
        return len(self.bodies) > 0

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData, x: np.ndarray, grad: np.ndarray,
              t: np.ndarray, end_moment: np.ndarray) -> None:
        """Add this step's reaction to qfrc_applied (and remove the last step's).

        x: vertex positions [m], grad: dE/dx [N], both (n_vertices, 3); t: tangents
        (n_edges, 3); end_moment (n_rods, 2): dE/dtheta [N m] of each rod's first and last
        edge (what a clamp there resists).
        """
        qfrc = self.generalized(model, data, x, grad, t, end_moment, self._qfrc)
        data.qfrc_applied[:] += qfrc - self._applied
        self._applied[:] = qfrc

    def generalized(self, model: mujoco.MjModel, data: mujoco.MjData, x: np.ndarray, grad: np.ndarray,
                    t: np.ndarray, end_moment: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The rods' generalized force on MuJoCo's dofs (into out, (nv,)) [N or N m], for
        the given state (arguments as :meth:`apply`'s, bodies placed as in ``data``, whose
        kinematics and com positions must be current); sets :attr:`force`, :attr:`torque`."""
        point = data.xpos[self.bodies]
        holder_wrench(x, grad, t, self.held_vertex, self.held_slot, self.clamp_slot, self.clamp_edge,
                      end_moment[self.clamp_rod, self.clamp_end], point, self.force, self.torque)
        out[:] = 0.0
        for s, b in enumerate(self.bodies):
            mujoco.mj_applyFT(model, data, self.force[s], self.torque[s], point[s], int(b), out)
        return out
