"""Rod vertices whose motion the user prescribes: held by bodies without dofs that move.

A vertex pinned (or an edge clamped) to a mocap body, or to a body welded to one, goes
wherever the user puts that body between two steps. Taken where it is now, with the free
vertices where the last step left them, the held edge starts the step turned (and, moved
more than an edge, stretched) by the user's move alone, and the stiff stretching's one
linearization about that kinked pose held the rod back: a 0.5 m rod of 100 edges pinned
to a hand moving sideways at 0.1 m/s (dt 1e-3, zero gravity) reached a mean velocity of
-0.94 m/s, backwards, in 0.1 s (at dt 1e-4 +0.043 m/s; the same rod held by a heavy body
on a slide, its motion solved in the step, +0.040 at dt 1e-3, +0.049 at 1e-2; a rigid rod
starts at +0.025). Backward Euler's Newton
iterations from that pose reach the right answer in three; the coupled holders of
:mod:`derods.sim.holders` get it in one, linearizing where the last step ended and
moving the held vertices within the step. So does this:

    (M + h^2 K_ff) a = F(x_last) - K_fh d - h K_ff v

with x_last the rods where the last step ended (the prescribed vertices where the last
step began) and d the prescribed vertices' move since: K_fh d, the rods' force change along
the move, from the Gauss-Newton blocks between free and prescribed vertices that the
compiled step computes anyway (every vertex given a place in its rod's band, the world's
band sliced from those, as the coupled holders do; the same blocks as K_ff, so that the
hand carrying the rod rigidly costs no force: exact differences there, not matching the
band's Gauss-Newton blocks, made a cable lifted off a table at dt 1e-2 hop and diverge).
A clamp's frame turns with its body at once (the twist its turn imposes acts in the step
it happens). The strain limit then measures the step's edges from x_last, held vertices
predicted at their new places. Rods in a world where bodies with dofs hold rods, and a
world with a ring, keep the other way: taken at the new pose, a stretched held edge
forgiven (:meth:`PrescribedVertices.strained`).

A step's strain check (:data:`derods.sim.divergence.MAX_STRAIN`) is on x_last, what the
last step did: a hand moved 6 mm in a step along a cable of 5 mm edges (a mocap cart whose
target starts at 0.6 m/s, dt 1e-2) is not a divergence.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba.coupling import band_product_into, free_band_into
from ..step import RodSet, evaluate
from .divergence import MAX_STRAIN
from .holders import chain_dofs, free_first, held_block_entries, vertex_places
from .layout import Layout


class PrescribedVertices:
    """The held vertices of open rods whose bodies have no dofs but move (mocap bodies and
    what is welded to them), and where they were when the last step began.

    vertex (k,): their indices in the flat vertex arrays; rod (k,): their rods.
    before (k, 3) [m]: their positions at the start of the last step (before the first:
    where the rods were built, ``layout.x0``).
    """

    def __init__(self, model: mujoco.MjModel, layout: Layout, rods: RodSet, rod_tw: np.ndarray):
        keep = np.array([len(chain_dofs(model, int(b))) == 0 for b in layout.moved_body], dtype=bool)
        rod = np.searchsorted(layout.v_off, layout.moved_vertex, side="right") - 1
        keep &= ~rods.closed[rod].astype(bool)
        self.vertex, self.rod = layout.moved_vertex[keep], rod[keep]
        self.before = layout.x0[self.vertex].copy()
        self._rods = rods
        self._x_last = np.zeros_like(layout.x0)
        #: Whether a step can take the move in it (:meth:`evaluate`): every rod open, its
        #: free vertices keeping their order in the band of all its vertices.
        self.in_step = bool(len(self.vertex)) and not rods.closed.any()
        if not self.in_step:
            return
        # Every vertex's place in its own rod's band, prescribed ones included: the
        # Gauss-Newton blocks K_fh between free and prescribed vertices come from the
        # compiled step itself (the world's band is sliced from those bands), as the
        # coupled holders' do (derods.sim.holders).
        self._place_all = vertex_places(rods)
        self._free_first, shares = free_first(layout, rods, self._place_all)
        self.in_step = shares
        self._bands = np.zeros((rods.n_rods, layout.band_rows, 3 * int(np.diff(rods.v_off).max())))
        self._band_of_rod = np.arange(rods.n_rods, dtype=np.int64)
        self._blocks = held_block_entries(layout, rods.v_off, self._place_all, self.vertex, self.rod, layout.band_rows)
        self._kd = np.zeros(layout.n)
        #: Those on rods held at both ends whose twist is the rank-one term (the step's rod_tw).
        self._twisted = np.flatnonzero(np.isin(self.rod, rod_tw))

    def __bool__(self) -> bool:
        return len(self.vertex) > 0

    def moved(self, x: np.ndarray) -> bool:
        """Whether any prescribed vertex moved since the last step began."""
        return not np.array_equal(x[self.vertex], self.before)

    def evaluate(self, step, x: np.ndarray) -> tuple[int, np.ndarray]:
        """The rods' forces and band for a step whose prescribed vertices moved to where x
        (n_vertices, 3) [m] has them: evaluated at x_last (the prescribed vertices where
        the last step began), the rods' force change along the move, K_fh d, added to the
        gradient (see the module's docstring), into ``step.terms`` and ``step.frames``.
        Returns (the first rod strained beyond MAX_STRAIN at x_last, or -1; x_last, shape
        (n_vertices, 3))."""
        lay, x_last = step.layout, self._x_last
        x_last[:] = x
        x_last[self.vertex] = self.before
        bad = evaluate(step.rods, step.frames, x_last, self._place_all, step.terms, step.ends, step.xmat, MAX_STRAIN,
                       self._bands, self._band_of_rod, step._rods_step)
        free_band_into(self._bands, self._free_first, lay.dof_off, step.terms.band)
        move = (x[self.vertex] - self.before).ravel()
        kd = self._kd
        kd[:] = 0.0
        band_product_into(self._bands, *self._blocks, move, kd)
        for c in self._twisted:  # a rod held at both ends: its rank-one twist term couples them too
            rod, v = self.rod[c], self.vertex[c]
            lo, hi = step.rods.v_off[rod], step.rods.v_off[rod + 1]
            free = lay.place[lo:hi] >= 0
            g = step.terms.g_tw
            kd.reshape(-1, 3)[lay.place[lo:hi][free]] += (step.terms.coef[rod] * (g[v] @ move[3 * c:3 * c + 3])
                                                          * g[lo:hi][free])
        step.terms.grad[lay.free_vertex] += kd.reshape(-1, 3)
        return bad, x_last

    def remember(self, x: np.ndarray) -> None:
        """Keep the prescribed vertices' positions in x (n_vertices, 3) [m], where this step
        begins."""
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
