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

from typing import NamedTuple

import mujoco
import numpy as np

from .._numba.coupling import free_band_into, gather_into, gather_positions
from ..stencil import ring_order
from ..step import Terms, evaluate
from .trees import TreeDynamics, tree_dofs, trees_of

class Stiffness(NamedTuple):
    """The rods' stiffness as the holders' dofs (k of them) and held points (H) see it."""

    k_f: np.ndarray   #: (n, k) [N/m or N/rad]: d grad_f / dq over the rods' free dofs
    k_q: np.ndarray   #: (k, k): d^2 E / dq^2
    k_fh: np.ndarray  #: (n, 3H) [N/m]: Gauss-Newton blocks between free dofs and held points
    k_hh: np.ndarray  #: (3H, 3H) [N/m]: the same among the held points
    jac: np.ndarray   #: (3H, k): the held points' motion per holder dof (mj_jac)


#: The central-difference step for K's columns [relative to the shortest edge for a
#: translation, in rad for a rotation]: the gradient is smooth; round-off stays below
#: 1e-8 of K.
FD_STEP = 1e-6


def chain_dofs(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The dofs that move ``body``: its own and its ancestors', shape (k,), int64."""
    dofs = []
    b = body
    while b > 0:
        dofs += range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b])
        b = model.body_parentid[b]
    return np.array(sorted(dofs), dtype=np.int64)


def rotational(model: mujoco.MjModel, dof: int) -> bool:
    """Whether a dof turns its body (hinge, ball, a free joint's last three)."""
    j = int(model.dof_jntid[dof])
    kind = int(model.jnt_type[j])  # an int: `numpy.int32 in (mjtJoint, ...)` is always False
    if kind == int(mujoco.mjtJoint.mjJNT_FREE):
        return dof - int(model.jnt_dofadr[j]) >= 3
    return kind in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_BALL))


def translation_mode(model: mujoco.MjModel, layout, dofs: np.ndarray, bodies) -> np.ndarray | None:
    """The motion of the holder dofs ``dofs`` (k, 3) that translates every held rod vertex
    rigidly along x, y, z, when the rods and their holders can translate freely together:
    every held vertex on one of ``bodies``' trees, each rooted in a free joint (whose
    first three dofs are world-frame translations). None otherwise (a vertex held by the
    world or a mocap body, a tree rooted in other joints: the momentum is not theirs)."""
    roots = {int(model.body_rootid[b]) for b in bodies}
    if len(layout.moved_vertex) != int(np.sum(layout.place < 0)):
        return None
    if not all(int(model.body_rootid[b]) in roots for b in layout.moved_body):
        return None
    mode = np.zeros((len(dofs), 3))
    for root in roots:
        j = int(model.body_jntadr[root])
        if model.body_jntnum[root] < 1 or model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            return None
        for a in range(3):
            mode[np.searchsorted(dofs, int(model.jnt_dofadr[j]) + a), a] = 1.0
    return mode


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


def gather(bands: np.ndarray, entries: tuple[np.ndarray, ...], shape: tuple[int, int]) -> np.ndarray:
    """The dense matrix of ``shape`` with the bands' (n_bands, rows, n) entries placed by
    :func:`band_entries`' index arrays."""
    out = np.empty(shape)
    gather_into(bands, *entries, out)
    return out


def invariant(k_qq: np.ndarray, k_qf_sum: np.ndarray, mode: np.ndarray) -> np.ndarray:
    """k_qq (k, k) made symmetric and exact on the translation mode (k, 3): the nearest
    symmetric matrix K with K mode = -k_qf_sum (k, 3) (= -K_qf 1, what translation
    invariance of the energy asks), by a symmetric rank-six correction."""
    k = 0.5 * (k_qq + k_qq.T)
    p = mode @ np.linalg.inv(mode.T @ mode)
    r = k @ mode + k_qf_sum
    return k - r @ p.T - p @ r.T + p @ (mode.T @ r) @ p.T


def gauss_newton(jac: np.ndarray, k_hh: np.ndarray) -> np.ndarray:
    """J^T K_hh J made symmetric: the Gauss-Newton K_qq [N/m or N m/rad] (k, k) of holder
    dofs whose held points move by jac (3H, k), k_hh (3H, 3H) the band's blocks among them."""
    gn = jac.T @ k_hh @ jac
    return 0.5 * (gn + gn.T)


def no_softer(k: np.ndarray, gn: np.ndarray) -> np.ndarray:
    """A block of K_qq (r, r) [N/m, N/rad or N m/rad] made no softer than its Gauss-Newton
    part gn (:func:`gauss_newton`): gn plus only the positive part (by eigenvalues) of what
    the differences add to it (the rods' geometric stiffness at the held points, the
    levers, a clamp's own bending and twisting).

    The band and K_fq are Gauss-Newton, PSD; the differenced block is exact and may be
    indefinite. Mixed, the holders' Schur complement can drift below their inertia: a 50 g
    arm on a hinge under a moving mocap base, clamping a 0.5 m rod, went from 0.0100 to
    below the arm's 0.00052 kg m^2 over ten steps while swinging back, and diverged (dt
    1e-2, the base moving 1 cm). Kept at least Gauss-Newton, the Schur complement stays
    above the inertia (a Schur complement of a PSD matrix adds to it); the negative part
    left out acts one step late, as in the rods' own band. Where clamps turn their frames,
    the cross terms between a body's translations and rotations carry the clamp's bending
    too, and the whole K_qq is kept so; where only points are held, the cross terms are the
    levers alone, and the whole kept so made a 1 g box landing on its pinned rod at dt 5e-3
    diverge: there only the rotations' block is. (The whole-K_qq rule for clamps was
    brought in against a clamping body whose pitch grew 3-5x a step; that was the stale
    com positions of :meth:`derods.sim.integrators.Step.elastic`, since fixed. Measured
    after the fix, the held sweep: 35 of 44 span cases right with the whole-K_qq rule, 34
    with the rotations' block alone, every other case the same.)"""
    lam, vec = np.linalg.eigh(0.5 * (k + k.T) - gn)
    return gn + (vec * np.maximum(lam, 0.0)) @ vec.T


class Holders:
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

    # -- the matrices -----------------------------------------------------------------
    def stiffness_columns(self, step) -> Stiffness:
        """K's columns over the holder dofs at the step's state (a :class:`Stiffness`):
        k_f (n, k) = d grad_f / dq [N/m or N/rad] over the rods' free dofs, k_q (k, k) =
        d^2 E / dq^2, and the pieces k_f is made of.

        k_f = K_fh J + F: K_fh the Gauss-Newton blocks between free and held vertices (the
        compiled step's, the same the band holds, so that a rigid translation of rod and
        holders costs no force: K_ff 1 + K_fh 1 = 0), J the held points' motion per dof
        and F what turning a clamp's frame does to the free vertices' force; J from
        mj_jac (exact: K is stiff, a difference's round-off in J leaked momentum), F and k_q
        by central differences (each dof moved by +-eps on a scratch copy of MuJoCo's
        data). Where rods and holders float freely (:func:`translation_mode`), k_q is made
        exact on the translations too (:func:`invariant`): linear momentum is kept.
        """
        if not self.turning:
            return self._slide_stiffness(step)
        m, d, lay, fr = step.model, step.data, step.layout, step.frames
        ds, xs, x = self._scratch, self._xs, step.x
        k = len(self.dofs)
        frame, k_q = np.zeros((lay.n, k)), np.zeros((k, k))
        ds.mocap_pos[:], ds.mocap_quat[:] = d.mocap_pos, d.mocap_quat
        if self._turns is None:  # clamps on bodies turn their frames (the world's layout: fixed)
            self._turns = bool(np.any(step.ends.body >= 0))
        turns = self._turns
        for j, dof in enumerate(self.dofs):
            if not self._eps_rot[j]:
                continue  # a translation: its row and column are the band's (below)
            eps = self._eps[j]
            gens, grads = [], []
            for sign in (1.0, -1.0):
                ds.qpos[:] = d.qpos
                self._dq[dof] = 1.0
                mujoco.mj_integratePos(m, ds.qpos, self._dq, sign * eps)
                self._dq[dof] = 0.0
                mujoco.mj_kinematics(m, ds)
                mujoco.mj_comPos(m, ds)
                gather_positions(lay.x0, ds.qpos, lay.qpos_adr, lay.free_vertex, ds.xpos, lay.moved_vertex,
                                 lay.moved_body, xs)
                frames = fr.copy()
                evaluate(step.rods, frames, xs, lay.place, self._terms, step.ends, ds.xmat)
                q = step.reactions.generalized(m, ds, xs, self._terms.grad, frames.t, self._terms.end_moment,
                                               self._qfrc)
                gens.append(q[self.dofs].copy())
                if turns and self._eps_rot[j]:
                    # the clamp frames turned, the vertices kept: F's column
                    evaluate(step.rods, fr.copy(), x, lay.place, self._terms, step.ends, ds.xmat)
                    grads.append(self._terms.grad[lay.free_vertex].ravel())
            k_q[:, j] = -(gens[0] - gens[1]) / (2.0 * eps)
            if grads:
                frame[:, j] = (grads[0] - grads[1]) / (2.0 * eps)
        jac = self._held_jacobian(m, d, x)  # exact
        k_fh = self.held_blocks(step)
        k_f = k_fh @ jac + frame
        # Translations: K_qq's rows and columns J^T K_hh J, the band's own Gauss-Newton blocks
        # (moving a body along a line moves its held points rigidly, no lever turns); the
        # rotations' by the differences above; all of it kept no softer than Gauss-Newton
        # (no_softer): the rotations' block alone where only points are held, the whole of
        # K_qq where clamps turn their frames.
        t, r = ~self._eps_rot, self._eps_rot
        k_hh = gather(self._bands, self._held_blocks, (3 * len(self.held), 3 * len(self.held)))
        gn = gauss_newton(jac, k_hh)
        if t.any():
            k_q[np.ix_(t, t)] = gn[np.ix_(t, t)]
            k_q[np.ix_(r, t)] = k_q[np.ix_(t, r)].T  # the rotations' columns, differenced, give both
        if turns:
            k_q = no_softer(k_q, gn)
        else:
            rr = np.ix_(r, r)
            k_q[rr] = no_softer(k_q[rr], gn[rr])
        if self._translation is not None:
            # K_qf times every free vertex moved along x, y, z: k_f's rows summed by axis
            k_q = invariant(k_q, k_f.reshape(-1, 3, k).sum(axis=0).T, self._translation)
        return Stiffness(k_f, k_q, k_fh, k_hh, jac)

    def _slide_stiffness(self, step) -> Stiffness:
        """:meth:`stiffness_columns` where every holder dof is a slide (carts, gantries): the
        held points move along the slides' axes, fixed in the world, so J is constant
        (taken once) and there is nothing to difference: K_qq = J^T K_hh J."""
        if self._slide_jac is None:
            self._slide_jac = self._held_jacobian(step.model, step.data, step.x)
        jac = self._slide_jac
        k_fh = self.held_blocks(step)
        k_hh = gather(self._bands, self._held_blocks, (3 * len(self.held), 3 * len(self.held)))
        return Stiffness(k_fh @ jac, gauss_newton(jac, k_hh), k_fh, k_hh, jac)

    def _held_jacobian(self, m: mujoco.MjModel, d: mujoco.MjData, x: np.ndarray) -> np.ndarray:
        """The held points' motion per holder dof (3H, k), by mj_jac at positions x
        (n_vertices, 3) [m] in data d's kinematics."""
        jac = np.empty((3 * len(self.held), len(self.dofs)))
        for c, (v, b) in enumerate(zip(self.held, self.held_body)):
            mujoco.mj_jac(m, d, self._jacp, self._jacr, x[v], int(b))
            jac[3 * c:3 * c + 3] = self._jacp[:, self.dofs]
        return jac

    def held_blocks(self, step) -> np.ndarray:
        """K_fh (n, 3H) [N/m]: the Gauss-Newton Hessian blocks between the rods' free dofs and
        the held vertices (with each held-both-ends rod's rank-one twist term), from one
        compiled evaluation in which every vertex has a place in its rod's band."""
        lay = step.layout
        if self._fresh:  # the step's own evaluation filled the bands (see evaluate)
            t = step.terms
            self._fresh = False
        else:
            t = self._terms_all
            evaluate(step.rods, step.frames.copy(), step.x, self._place_all, t, step.ends, step.xmat, np.inf,
                     self._bands, self._band_of_rod)
        out = gather(self._bands, self._blocks, (lay.n, 3 * len(self.held)))
        if self._twisted is None:  # which held vertices' rods are held at both ends (fixed at compile)
            self._twisted = np.flatnonzero(np.isin(self.rod_of_held, step.rod_tw))
        v_off = step.rods.v_off
        for c in self._twisted:
            h, rod = self.held[c], self.rod_of_held[c]
            lo, hi = v_off[rod], v_off[rod + 1]
            free = lay.place[lo:hi] >= 0
            g_f = np.zeros(lay.n)
            g_f.reshape(-1, 3)[lay.place[lo:hi][free]] = t.g_tw[lo:hi][free]
            out[:, 3 * c:3 * c + 3] += step.terms.coef[rod] * np.outer(g_f, t.g_tw[h])
        return out
