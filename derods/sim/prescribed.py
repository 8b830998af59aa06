"""Rod vertices whose motion the user prescribes: held by bodies without dofs that move.

A vertex pinned (or an edge clamped) to a mocap body, or to a body welded to one, goes
wherever the user puts that body between two steps: a mocap cart whose target starts
at 0.6 m/s moves 6 mm in the first step of dt 1e-2, more than a 5 mm edge. The step
finds the held vertex there and its free neighbour where the last step left it, so the
edge between them starts the step stretched by the user's motion, not by anything the
last step did (measured: a 0.5 m cable of 100 edges on such a cart started its second
step at strain 1.18 and was stopped as diverged; let through, the implicit step pulled
the cable after the cart and the strain was back under 1e-3 after that step).

The divergence check's strain limit (:data:`derods.sim.divergence.MAX_STRAIN`) is meant
for what a step did; so a rod found strained beyond it is measured again with its
prescribed vertices where they were when the last step began (the pose that step
solved with), and stopped only if it is strained there too. The forces themselves stay
at the held vertices' new places: linearized there the step sees the edge's new
direction (linearized at the old pose, a sideways move of the holder would have no
stretching force against it, the Gauss-Newton blocks being along the edge).
"""

from __future__ import annotations

import mujoco
import numpy as np

from ..step import RodSet
from .layout import Layout


def without_dofs(model: mujoco.MjModel, bodies: np.ndarray) -> np.ndarray:
    """Which of ``bodies`` (k,) no joint moves (neither theirs nor an ancestor's), shape (k,) bool."""
    out = np.zeros(len(bodies), dtype=bool)
    for i, b in enumerate(bodies):
        b = int(b)
        while b > 0 and model.body_dofnum[b] == 0:
            b = int(model.body_parentid[b])
        out[i] = b == 0
    return out


class PrescribedVertices:
    """The held vertices of open rods whose bodies have no dofs but move (mocap bodies and
    what is welded to them), and where they were when the last step began.

    vertex (k,): their indices in the flat vertex arrays; rod (k,): their rods.
    before (k, 3) [m]: their positions at the start of the last step (before the first:
    where the rods were built, ``layout.x0``).
    """

    def __init__(self, model: mujoco.MjModel, layout: Layout, rods: RodSet):
        keep = without_dofs(model, layout.moved_body)
        rod = np.searchsorted(layout.v_off, layout.moved_vertex, side="right") - 1
        keep &= ~rods.closed[rod].astype(bool)
        self.vertex, self.rod = layout.moved_vertex[keep], rod[keep]
        self.before = layout.x0[self.vertex].copy()
        self._rods = rods

    def __bool__(self) -> bool:
        return len(self.vertex) > 0

    def remember(self, x: np.ndarray) -> None:
        """Keep their positions in x (n_vertices, 3) [m], the ones this step begins from."""
        self.before[:] = x[self.vertex]

    def strained(self, x: np.ndarray, strain: np.ndarray, limit: float) -> int:
        """The first rod strained beyond ``limit`` at x (n_vertices, 3) [m] once its
        prescribed vertices are put back where the last step began, among the rods whose
        largest |strain| (n_rods,) at x exceeds it (or is not finite); -1 if none is."""
        rods = self._rods
        for i in np.flatnonzero(~(strain <= limit)):
            mine = self.rod == i
            if not mine.any():
                return int(i)
            xi = x[rods.v_off[i]:rods.v_off[i + 1]].copy()
            xi[self.vertex[mine] - rods.v_off[i]] = self.before[mine]
            length = np.linalg.norm(np.diff(xi, axis=0), axis=1)
            rest = rods.rest_len[rods.e_off[i]:rods.e_off[i + 1]]
            if not np.max(np.abs(length / rest - 1.0)) <= limit:
                return int(i)
        return -1
