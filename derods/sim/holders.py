"""Bodies that hold rod ends, coupled implicitly to the rods' step.

A vertex pinned or an edge clamped to a body with dofs (a free joint, slides, hinges,
chains of them) moves with that body, and the rod's force and twisting moment reach
the body. Applied one step late (:class:`derods.sim.clamps.Reactions` alone), the
rod's stiff stretching makes a light body diverge: the body's mass must exceed about
k_s h / 4 (measured: every body of 1e-3 to 1e3 times a 0.3 kg rod's mass diverged at
dt = 1e-2). Here the holders' dofs q enter the rods' implicit step instead (backward
Euler, linearized about the start of the step, s = h^2 + h b):

    A a_f + s K_fq a_q = r_f - (b + h) K_fq v_q                          (rod dofs)
    (M - h D) a_q + s (K_qf a_f + K_qq a_q) = f_q - (b + h) (K_qf v_f + K_qq v_q)

with E the rods' energy, K_fq = d grad_f E / dq and K_qq = d^2 E / dq^2 (so K_qf =
K_fq^T), f_q everything MuJoCo puts on the holders' dofs this step but the contact rows derods
solves (the rods' reaction at the start of the step, actuators, damping, MuJoCo's
force of the constraints it keeps), M MuJoCo's mass matrix and D its velocity derivative (``qDeriv``: joint
damping, actuators' kv, as MuJoCo's implicit integrators take it, or the joint damping
Euler's takes implicitly). Eliminating a_f with the rods' factored A (one banded solve
per holder dof) leaves a small dense system, the rods' stiffness as the holders feel
it being a Schur complement (A keeps its band):

    (M - h D + s K_qq - s^2 K_qf A^-1 K_fq) a_q = f_q - (b + h)(...) - s K_qf y0.

K_fq = K_fh J + F: K_fh the Gauss-Newton blocks between free and held vertices, from
the compiled step itself (every vertex given a place in its rod's band), J the held
points' Jacobian (mj_jac), F what turning a clamp's frame does to the free vertices'
force; F and K_qq come from central differences over the holder dofs (each dof moved
by +-eps through ``mj_integratePos``, MuJoCo's kinematics on a scratch copy of the
data, the rods' gradient and generalized reaction evaluated there), so a clamp's
twisting moment and turning edge are in them. Using the band's own blocks (rather than
exact differences, which the band's Gauss-Newton blocks do not match) makes a rigid
translation of rods and holders cost no force: a free rod pinned to a free body keeps
its linear momentum to 2e-10 (1.8e-3 .. 2e-2 with differenced columns). A clamp's
second held vertex sits off its body's origin, and MuJoCo's Euler and implicitfast
integrators do not keep the momentum of a spinning body with an off-centre mass
(measured alone, no rods: 8e-4 .. 1e-3 over 200 steps; RK4 6e-12), which bounds a
clamped pair's momentum the same way.

The dofs solved are those of the kinematic trees the holders belong to (M is block
diagonal over trees, so MuJoCo's own implicit solve of those rows then reproduces a_q
exactly, :mod:`derods.sim.trees`); trees with no rod attached stay MuJoCo's alone. The
differences evaluate every rod of the world (2 per holder dof, 4 for a rotation when
clamps turn): cheap for the rods a robot holds, not meant for a head of hair on a body
with dofs (hair rides a mocap head).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba.coupling import free_band_into
from ..stencil import ring_order
from ..step import Terms, evaluate
from .holder_stiffness import FD_STEP, HolderStiffness, rotational, translation_mode
from .trees import TreeDynamics, tree_dofs, trees_of

def chain_dofs(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The dofs that move ``body``: its own and its ancestors', shape (k,), int64."""
    dofs = []
    b = body
    while b > 0:
        dofs += range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b])
        b = model.body_parentid[b]
    return np.array(sorted(dofs), dtype=np.int64)


def band_entries(pairs, band_rows: int) -> tuple[np.ndarray, ...]:
    """Index arrays that gather 3 x 3 blocks of symmetric matrices kept as lower bands.

    pairs: (band, place i, place j, block row, block column) per block: the block between
    vertex places i and j of band ``band`` goes to rows 3 block row + (0..2) and columns
    3 block column + (0..2) of the output; entries beyond the band are left out (zero).
    Returns (band, band row, band column, output row, output column), int64, for
    :func:`gather`."""
    src, dst = [], []
    for band, pi, pj, bi, bj in pairs:
        for a in range(3):
            for b in range(3):
                i, j = 3 * pi + a, 3 * pj + b
                if abs(i - j) < band_rows:
                    src.append((band, abs(i - j), min(i, j)))
                    dst.append((3 * bi + a, 3 * bj + b))
    src, dst = np.array(src, dtype=np.int64).reshape(-1, 3), np.array(dst, dtype=np.int64).reshape(-1, 2)
    return src[:, 0], src[:, 1], src[:, 2], dst[:, 0], dst[:, 1]


def vertex_places(rods) -> np.ndarray:
    """Every vertex's place in its own rod's band, held ones included (a ring's in ring
    order), shape (n_vertices,), int64: the compiled step then gives the Gauss-Newton blocks
    between free and held vertices too (evaluated into one band per rod)."""
    nvs = np.diff(rods.v_off)
    return np.concatenate([np.argsort(ring_order(n)) if rods.closed[i] else np.arange(n)
                           for i, n in enumerate(nvs)]).astype(np.int64)


def free_first(layout, rods, place_all: np.ndarray) -> tuple[np.ndarray, bool]:
    """Where each rod's free vertices start in its all-vertex band (``place_all``,
    :func:`vertex_places`), shape (n_rods,), and whether every rod's free vertices keep
    their solve order there: then the world's band is a slice of those bands
    (:func:`derods._numba.coupling.free_band_into`) and one evaluation serves both."""
    shares = True
    first = np.zeros(rods.n_rods, dtype=np.int64)
    for i in range(rods.n_rods):
        v = np.arange(rods.v_off[i], rods.v_off[i + 1])
        free = v[layout.place[v] >= 0]
        if not len(free):
            continue
        own = place_all[free]
        first[i] = own.min()
        if not np.array_equal(own - first[i], layout.place[free] - layout.dof_off[i] // 3):
            shares = False
    return first, shares


def held_block_entries(layout, v_off: np.ndarray, place_all: np.ndarray, held: np.ndarray, rod_of_held: np.ndarray,
                       band_rows: int) -> tuple[np.ndarray, ...]:
    """Where K_fh's entries sit in the all-vertex bands: every free dof within the band of a
    held vertex ``held`` (k,) of rod ``rod_of_held`` (k,), its 3 columns the k-th block
    (static: the layout fixes them; see :func:`band_entries`)."""
    reach = band_rows // 3 + 1  # vertices either side within reach of the band
    pairs = [(rod, place_all[v], place_all[h], layout.place[v], c)
             for c, (h, rod) in enumerate(zip(held, rod_of_held))
             for v in range(max(v_off[rod], h - reach), min(v_off[rod + 1], h + reach + 1)) if layout.place[v] >= 0]
    return band_entries(pairs, band_rows)


class Holders(HolderStiffness):
    """The bodies with dofs that hold rod ends, and the matrices of the coupled step (solved
    with the contacts by :mod:`derods.sim.coupled`). Built once from
    the layout; ``bool(holders)`` is False (and costs nothing) when there are none.

    dofs (k,): the dofs that move a held vertex or clamp (the FD columns); tree (m,):
    every dof of their kinematic trees (the solved rows); both int64, sorted.
    """

    def __init__(self, model: mujoco.MjModel, layout, rods, band_rows: int, reactions):
        bodies = [int(b) for b in reactions.bodies if len(chain_dofs(model, int(b)))]
        self.bodies = np.array(bodies, dtype=np.int64)
        self.dofs = np.unique(np.concatenate([chain_dofs(model, b) for b in bodies])) if bodies \
            else np.zeros(0, dtype=np.int64)
        #: The trees of these bodies, and all their dofs (the solved rows).
        self.trees = trees_of(model, bodies)
        self.tree = tree_dofs(model, self.trees)
        self._in_tree = np.searchsorted(self.tree, self.dofs)
        if not bodies:
            return
        self._scratch = mujoco.MjData(model)
        self._terms = Terms.empty(rods.n_rods, rods.n_vertices, layout.n, band_rows)
        self._xs = np.zeros_like(layout.x0)
        self._qfrc = np.zeros(model.nv)
        self._dq = np.zeros(model.nv)
        edge = float(np.min(rods.rest_len))
        #: The rods' shortest rest edge length [m].
        self.shortest_edge = edge
        self._eps_rot = np.array([rotational(model, int(j)) for j in self.dofs])
        #: Whether a held point can turn (a rotational dof moves it): then it moves on arcs;
        #: if not, every holder dof is a slide with slides above it (fixed axes).
        self.turning = bool(self._eps_rot.any())
        self._eps = np.where(self._eps_rot, FD_STEP, FD_STEP * edge)
        self._band_of_rod = np.arange(rods.n_rods, dtype=np.int64)
        self._jacp, self._jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        coupled = np.isin(reactions.bodies[reactions.held_slot], self.bodies)
        #: Held vertices on these bodies (H,), and the rod of each.
        self.held = reactions.held_vertex[coupled]
        #: The vertex body of each held vertex (riding its holder).
        self.held_body = np.asarray(layout.body, dtype=np.int64)[self.held]
        #: The rod of each held vertex, and the rods so held (ascending).
        self.rod_of_held = np.searchsorted(rods.v_off, self.held, side="right") - 1
        self.rods = np.unique(self.rod_of_held)
        # Every vertex's place in its own rod's band, held ones included: the Gauss-Newton
        # blocks between free and held vertices come from the compiled step itself.
        self._place_all = vertex_places(rods)
        self._bands = np.zeros((rods.n_rods, band_rows, 3 * int(np.diff(rods.v_off).max())))
        self._terms_all = Terms.empty(rods.n_rods, rods.n_vertices, 0, band_rows)
        self._translation = translation_mode(model, layout, self.dofs, self.bodies)
        self._dynamics = TreeDynamics(model)
        self._blocks = held_block_entries(layout, rods.v_off, self._place_all, self.held, self.rod_of_held,
                                          band_rows)
        self._held_blocks = self._held_entries(band_rows)
        self._turns = None
        self._twisted = None
        self._slide_jac = None
        #: Whether the world's step evaluates the rods once for both bands (:meth:`evaluate`).
        self._free_first, self.shares_band = free_first(layout, rods, self._place_all)
        self._fresh = False

    def evaluate(self, step, x: np.ndarray, strain_limit: float) -> int:
        """The world's forces and band at positions x (n_vertices, 3) [m] from one
        compiled evaluation in which every vertex has a place in its rod's band: the
        world's band (``step.terms.band``) is sliced from it, and :meth:`held_blocks`
        reads its blocks between free and held vertices without evaluating the rods
        again. Returns what :func:`derods.step.evaluate` does."""
        bad = evaluate(step.rods, step.frames, x, self._place_all, step.terms, step.ends, step.xmat, strain_limit,
                       self._bands, self._band_of_rod, step._rods_step)
        free_band_into(self._bands, self._free_first, step.layout.dof_off, step.terms.band)
        self._fresh = True
        return bad

    def _held_entries(self, band_rows: int) -> tuple[np.ndarray, ...]:
        """Where K_hh's entries sit in the bands: the blocks among the held vertices of one rod."""
        held = list(enumerate(zip(self.held, self.rod_of_held)))
        pairs = [(r1, self._place_all[h1], self._place_all[h2], c1, c2)
                 for c1, (h1, r1) in held for c2, (h2, r2) in held if r1 == r2]
        return band_entries(pairs, band_rows)

    def __bool__(self) -> bool:
        return len(self.dofs) > 0
