"""Contact between rods and the scene, solved in the metric of the implicit step.

MuJoCo finds the contacts and sets up its soft-constraint rows for them (the
Jacobian ``efc_J``, reference accelerations ``efc_aref``, weights ``efc_D``).
Its own solver would find the contact forces with the bare vertex masses M,
as if each vertex were free; but within an implicit step a vertex is bound to
its neighbours by the stiffness h^2 K, and a contact force computed for the
wrong inertia is either far too weak (the rod sinks in) or, lagged to the
next step, pumps energy (chatter). So derods solves the same problem MuJoCo
solves, in the right metric A = M (1 + h a_m) + (h^2 + h b) K:

    minimize_a  1/2 (a - a0)^T A (a - a0) + sum_i 1/2 D_i min(J_i a - aref_i, 0)^2,

MuJoCo's primal formulation for pyramidal (and frictionless) contacts (elliptic
ones add their cone's cost), with
a0 the unconstrained implicit acceleration. Each row of a rod touching a
static obstacle touches at most two neighbouring vertices, so the Hessian
A + J^T D J stays banded and Newton's method costs one banded Cholesky per
iteration. Rows that touch distant parts of a rod (self-contact, as in a knot)
or two rods enter the Newton step as a low-rank update. Rows that couple a rod
to other moving bodies join the solve with those bodies' whole kinematic trees:
a tree of a few dofs as one more band block, a larger one (an arm with its hand)
as the border of the band, by its Schur complement in each Newton step; the
equalities and joint limits among the joined trees join too
(:mod:`derods.sim.tree_rows`). An elliptic contact's rows are solved as its cone,
MuJoCo's own elliptic cost (:mod:`derods._numba.cones`). Rows that reach bodies
beyond them keep the force MuJoCo's own solver computed for them in the same step.

Two corrections of MuJoCo's reference accelerations come first
(:class:`derods.sim.contact_reference.ReferenceCorrection`). Bodies that move without dofs (mocap bodies,
posed by the user each step) have no velocity for MuJoCo, so a row against one
would only see the penetration the move left, never the approach: they get the
velocity of their last move. And a rod with a contact margin (speculative
contacts, ``ContactParams.margin``) has rows before it touches: such a row only
keeps the end-of-step position from crossing the surface, instead of MuJoCo's
reading of a margin as a skin to push out of. Discrete collision detection
otherwise finds a rod moving at v only once it is up to v h inside.

Per step, one compiled call (:func:`derods._numba.contact.contact_step`) does it
all: split MuJoCo's rows, reweight them for the implicit metric
(:func:`derods._numba.row_weights.row_weights`), and run Newton's method
(:func:`derods._numba.contact_newton.newton`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba import contact as _k
from .._numba import parallel
from .._numba.banded import cholesky_into
from .._numba.calls import Bound
from .._numba.cone_rows import ConeContacts
from .._numba.contact_newton import Border, newton
from .._numba.row_split import efc_triplets
from .._numba.coupled import bordered_rows, row_forces_into
from .._numba.dense import lu_factor
from .._numba.implicit import sm_solve_into
from .._numba.solved_rows import rows_touch_rods
from ..stencil import XX_BANDWIDTH
from .implicit import ImplicitSystem
from .tree_rows import SolvableRows, solvable_rows
from .trees import TreeDynamics, tree_dofs

#: Width of a row's dof window that keeps the Hessian banded.
WINDOW = XX_BANDWIDTH + 1
_PYRAMIDAL = int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL)
_FRICTIONLESS = int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS)
_ELLIPTIC = int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC)
#: The constraint types derods re-solves: MuJoCo's pyramidal, frictionless and elliptic
#: contacts (an elliptic one as its cone, :mod:`derods._numba.cones`).
SUPPORTED = np.array([_PYRAMIDAL, _FRICTIONLESS, _ELLIPTIC])
#: Newton's method: iteration cap, and the tolerance on the gradient relative to the
#: problem's force scale.
MAX_ITER = 30
TOL = 1e-10


#: A step's blocks go on two threads only with at least this many rows (MuJoCo's, nefc)
#: and the lighter run holding at least SPLIT_SHARE of the work (rows plus dofs). Measured
#: on the 2-core VM, rods of 32 vertices lying on a floor (128 rows each; median step, one
#: thread against two, three interleaved runs, benchmarks/bench_contact_threads.py --force):
#: 10 rods 1.16x slower on two, 30 rods 1.13x slower, 50 rods (6400 rows) 0.84-0.86x, 100
#: rods 0.75-0.81x.
SPLIT_MIN_ROWS = 6000
SPLIT_SHARE = 0.3


def split_blocks(start: np.ndarray, row_start: np.ndarray, min_rows: int = SPLIT_MIN_ROWS) -> int | None:
    """Where a step's blocks split into two runs of nearly equal work (rows plus dofs; start,
    row_start: each block's dofs and rows, :class:`derods._numba.contact.Blocks`), or None
    when they should stay on one thread (one block, fewer rows than min_rows, no balanced
    cut)."""
    n = len(start) - 1
    if n < 2 or row_start[-1] < min_rows:
        return None
    work = np.cumsum(np.diff(start) + np.diff(row_start))
    mid = int(np.searchsorted(work, 0.5 * work[-1])) + 1
    mid = min(max(mid, 1), n - 1)
    first = work[mid - 1]
    if min(first, work[-1] - first) < SPLIT_SHARE * work[-1]:
        return None
    return mid


def cones_or_none(cones):
    """The cones (:class:`derods._numba.cones.Cones`) as Newton takes them: None for none,
    so that a solve without cones runs the code compiled without them."""
    return cones if len(cones.dim) else None


class ContactStep:
    """The per-step contact stage of a world: MuJoCo's rows after its forward pass in,
    the corrected acceleration of the rod dofs out (one compiled call).

    model: the compiled model; local_of_dof (nv,): each MuJoCo dof's place among the
    rods' free dofs, -1 elsewhere; dof_off (n_rods + 1,): each rod's range of them.
    After :meth:`__call__`, ``force`` (n,) [N] holds the constraint force on the rod
    dofs.

    Bodies touching rods: the dofs of a kinematic tree that a row binds to a rod (a
    gripper's finger pressing on a cable) join the solve for that step, as one more
    "rod" whose metric is MuJoCo's M - h D on the tree (:mod:`derods.sim.trees`) and
    whose unconstrained acceleration is what MuJoCo's integrator would give it without
    constraints. So a contact sees the rod's stiffness and the body's inertia at once
    (MuJoCo alone would see a bare vertex mass, and a servo-driven finger would squeeze
    through the rod); the tree's qacc is then written back. A tree of more dofs than the
    band holds (``band_rows``: an arm with a gripper) joins as the band's border instead
    (:meth:`_with_border`); ``excluded`` trees (solved elsewhere: holders) keep MuJoCo's
    forces.
    """

    def __init__(self, model: mujoco.MjModel, local_of_dof: np.ndarray, dof_off: np.ndarray, n: int,
                 band_rows: int = WINDOW, excluded=()):
        self.model = model
        self.is_sparse = bool(mujoco.mj_isSparse(model))
        self.nv = model.nv
        self.local_of_dof = np.ascontiguousarray(local_of_dof, dtype=np.int64)
        self.dof_off = np.ascontiguousarray(dof_off, dtype=np.int64)
        self.force = np.zeros(n)
        self.a = np.zeros(n)
        self._force_is_zero = True
        # Each dof's tree if the tree may join a contact solve, else -1: in the band, or
        # as its border (large).
        dof_tree = model.dof_treeid.astype(np.int64)
        joins = model.tree_dofnum > 0
        joins[dof_tree[self.local_of_dof >= 0]] = False  # the rods' own trees
        joins[np.asarray(excluded, dtype=np.int64)] = False
        self._large = model.tree_dofnum > band_rows
        self._dof_tree = np.where(joins[dof_tree], dof_tree, -1)
        self.bodies = bool(np.any(self._dof_tree >= 0))
        self._dynamics = TreeDynamics(model) if self.bodies else None
        self._contact_step = Bound(_k.contact_step)
        # Blocks of rods on two threads (see _solve): when more than one rod may touch
        # something and the process has the cores.
        self._threaded = len(self.dof_off) > 2 and parallel.threads() >= 2
        #: The rows (nefc) from which the blocks may go on two threads (SPLIT_MIN_ROWS).
        self.split_min_rows = SPLIT_MIN_ROWS
        self._blocks = Bound(_k.contact_blocks)
        self._solve_blocks = [Bound(_k.solve_blocks), Bound(_k.solve_blocks)]  # one a thread
        #: Elliptic cones: MuJoCo's contacts are read for them each step (else never).
        self.elliptic = model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
        none = np.zeros(0, dtype=np.int32)
        self._no_cone_contacts = ConeContacts(_ELLIPTIC, none, none, none, np.zeros(0), np.zeros((0, 5)), np.zeros(0))
        #: The body trees (MuJoCo tree ids) whose dofs joined the last step's solve.
        self.joined_trees = np.zeros(0, dtype=np.int64)

    def __call__(self, data: mujoco.MjData, system: ImplicitSystem, a0: np.ndarray) -> np.ndarray | None:
        """The acceleration [m/s^2] (n,) with contacts, or None if no row touches a rod."""
        nefc = data.nefc
        self.joined_trees = np.zeros(0, dtype=np.int64)
        if nefc:
            trees = self._touching_trees(data) if self.bodies else ()
            self.joined_trees = np.asarray(trees, dtype=np.int64)
            large = self._large[trees] if len(trees) else None
            if large is not None and large.any():
                touched = self._with_border(data, system, a0, trees[~large], trees[large])
            elif len(trees):
                touched = self._with_trees(data, system, a0, trees)
            else:
                touched = self._solve(data, system.arrays, self.local_of_dof, self.dof_off, a0, self.a, self.force)
            if touched:
                self._force_is_zero = False
                return self.a
        if not self._force_is_zero:
            self.force[:] = 0.0
            self._force_is_zero = True
        return None

    def _solve(self, data, system, local_of_dof, dof_off, a0, a_out, force_out, efc=None) -> int:
        """The compiled contact stage over the given dofs (the rods', or the rods' and some
        trees'; system: A over them, :class:`derods._numba.implicit.System`), into a_out and
        force_out; 1 if a row touched them. efc: the rows (default: MuJoCo's, :meth:`rows`)."""
        rest = (SUPPORTED, local_of_dof, dof_off, WINDOW, system, a0, a_out, force_out, MAX_ITER, TOL)
        # The rows are views of MuJoCo's data made afresh each step: flat arrays of its own
        # (not views into an array of structs, as data.contact's are, whose layout changes
        # with their count), so their types are the data's (and so are those of rows made
        # from them, tree_rows.solvable_rows); the contacts' for cones, contiguous copies.
        rows = self.rows(data) if efc is None else efc
        if self._threaded and efc is None and data.nefc >= self.split_min_rows:
            return self._solve_threaded(data, rows, system, local_of_dof, dof_off, a0, a_out, force_out)
        if self.elliptic:
            return self._contact_step.keyed((data, data) + rest, (rows, self.cone_contacts(data)) + rest)
        return self._contact_step.keyed((data, None) + rest, (rows, None) + rest)

    def _solve_threaded(self, data, rows, system, local_of_dof, dof_off, a0, a_out, force_out) -> int:
        """:meth:`_solve` of the rods' own rows as its two compiled halves: the blocks
        (:func:`derods._numba.contact.contact_blocks`), then, when they split into two runs of
        nearly equal work worth a hand-off (:func:`split_blocks`), the second run on a worker
        thread while this one solves the first (:func:`derods._numba.contact.solve_blocks`
        releases the GIL; the runs write disjoint dofs and rows). Each block's arithmetic is
        the same as in one call."""
        blocks = self._blocks.keyed((data, SUPPORTED, local_of_dof, dof_off, system, a0, a_out, force_out),
                                    (rows, SUPPORTED, local_of_dof, dof_off, system, a0, a_out, force_out))
        n = blocks.n_blocks
        if n == 0:
            return 0
        cones, cone_key = (self.cone_contacts(data), data) if self.elliptic else (None, None)
        key = (data, cone_key, data, int, int, local_of_dof, dof_off, WINDOW, system, a0, a_out, force_out, MAX_ITER,
               TOL)

        def run(thread: int, b0: int, b1: int) -> None:  # blocks b0 .. b1 - 1
            self._solve_blocks[thread].keyed(key, (rows, cones, blocks, b0, b1, local_of_dof, dof_off, WINDOW, system,
                                                   a0, a_out, force_out, MAX_ITER, TOL))

        mid = split_blocks(blocks.start, blocks.row_start, self.split_min_rows)
        if mid is None:
            run(0, 0, n)
            return 1
        second = parallel.workers().submit(run, 1, mid, n)
        try:
            run(0, 0, mid)
        finally:
            second.result()
        return 1

    def cone_contacts(self, data: mujoco.MjData) -> ConeContacts | None:
        """MuJoCo's contacts as the stage reads them for elliptic cones (None in a model
        without them)."""
        if not self.elliptic:
            return None
        if not data.ncon:
            return self._no_cone_contacts
        con = data.contact
        return ConeContacts(_ELLIPTIC, data.efc_id, np.ascontiguousarray(con.efc_address),
                            np.ascontiguousarray(con.dim), np.ascontiguousarray(con.mu),
                            np.ascontiguousarray(con.friction), np.ascontiguousarray(con.dist))

    def _tree_rows(self, data, trees) -> tuple[_k.Efc, SolvableRows | None]:
        """MuJoCo's rows with the equalities and joint limits among the joined ``trees``
        solvable (:mod:`derods.sim.tree_rows`), and what to finish them with (None: none)."""
        efc = self.rows(data)
        inside = np.zeros(self.nv, dtype=bool)
        inside[tree_dofs(self.model, trees)] = True
        solvable = solvable_rows(efc, data, inside)
        return (efc, None) if solvable is None else (solvable.efc, solvable)

    def touches(self, data: mujoco.MjData) -> bool:
        """Whether a constraint row of this step touches a rod dof (the stage would solve
        rows, :meth:`__call__` would not return None), without solving them."""
        return bool(data.nefc) and rows_touch_rods(self.is_sparse, data.nefc, self.nv, data.efc_J,
                                                   data.efc_J_rownnz, data.efc_J_rowadr, data.efc_J_colind,
                                                   self.local_of_dof)

    def rows(self, data: mujoco.MjData) -> _k.Efc:
        """MuJoCo's constraint rows of this step, as the compiled stage reads them."""
        return _k.Efc(self.is_sparse, data.nefc, self.nv, data.efc_J, data.efc_J_rownnz, data.efc_J_rowadr,
                      data.efc_J_colind, data.efc_type, data.efc_force, data.efc_aref, data.efc_R, data.efc_diagA)

    def _touching_trees(self, data: mujoco.MjData) -> np.ndarray:
        """The trees that a constraint row binds to a rod dof this step (sorted)."""
        row, col, _ = efc_triplets(self.is_sparse, data.nefc, self.nv, data.efc_J, data.efc_J_rownnz,
                                   data.efc_J_rowadr, data.efc_J_colind)
        on_rod = np.zeros(data.nefc, dtype=bool)
        on_rod[row[self.local_of_dof[col] >= 0]] = True
        trees = self._dof_tree[col[on_rod[row]]]
        return np.unique(trees[trees >= 0])

    def small_trees(self, trees: np.ndarray) -> np.ndarray:
        """Those of ``trees`` (tree ids) that fit the band as blocks of their own."""
        return trees[~self._large[trees]]

    def _with_border(self, data, system, a0, small, large) -> int:
        """The contact solve with the ``small`` trees' dofs appended to the rods' and the
        ``large`` trees' as its border (:class:`derods._numba.contact_newton.Border`): their
        metric M - h D, no stiffness between them and the rods (H_fq = 0), the rows that
        touch only these dofs derods' (the trees' own contacts too), the others' forces
        MuJoCo's. Every rod is in the one block."""
        m, n = self.model, len(a0)
        ext = WithTrees(m, data, system, self, small, a0)
        dofs = tree_dofs(m, large)
        k = len(dofs)
        border_of_dof = np.full(self.nv, -1, dtype=np.int64)
        border_of_dof[dofs] = np.arange(k)
        metric = self._dynamics.metric(m, data, dofs)
        efc, solvable = self._tree_rows(data, np.concatenate([small, large]))
        rows = bordered_rows(efc, self.cone_contacts(data), SUPPORTED, np.zeros(0, dtype=np.bool_),
                             ext.local_of_dof, border_of_dof, ext.n, k, WINDOW)
        start = ext.a0.copy()
        if rows.ext.any():
            e = rows.ext.copy()
            sm_solve_into(ext.system, e)
            start += e
        a_q = np.linalg.solve(metric, data.qfrc_smooth[dofs] + rows.ext_q)
        if not len(rows.efc):
            a, lam = start, np.zeros(0)
        else:
            lu, piv = metric.copy(), np.zeros(k, dtype=np.int64)
            lu_factor(lu, piv)  # the border's Schur complement: H_qq itself, H_fq being 0
            no_coupling = np.zeros((ext.n, k))
            weights = _k.row_weights(ext.system, rows.rows, no_coupling, rows.jq, lu, piv, rows.ratio,
                                     np.zeros(0, dtype=np.int64), rows.cones)
            a, a_q, lam, _ = newton(ext.system, start, rows.rows, rows.aref, weights,
                                    Border(no_coupling, metric, rows.jq, a_q), cones_or_none(rows.cones), MAX_ITER,
                                    TOL)
        row_forces_into(rows, lam, self.force, efc.force)
        if solvable is not None:
            solvable.finish(data)
        self.a[:] = a[:n]
        ext.write(data, a[n:])
        self._dynamics.write(data, dofs, metric, a_q)
        return 1

    def _with_trees(self, data, system, a0, trees) -> int:
        """The contact solve with the given trees' dofs appended to the rods' (see the class)."""
        n, sizes = len(a0), self.model.tree_dofnum[trees].astype(np.int64)
        ext = WithTrees(self.model, data, system, self, trees, a0)
        dof_off = np.concatenate([self.dof_off, n + np.cumsum(sizes)])
        a_out, force_out = np.zeros(ext.n), np.zeros(ext.n)
        efc, solvable = self._tree_rows(data, trees)
        touched = self._solve(data, ext.system, ext.local_of_dof, dof_off, ext.a0, a_out, force_out, efc)
        if solvable is not None:
            solvable.finish(data)
        self.a[:], self.force[:] = a_out[:n], force_out[:n]
        ext.write(data, a_out[n:])
        return touched


class WithTrees:
    """The rods' factored system (n dofs) with the k dofs of the kinematic trees ``trees``
    appended as band blocks of their M - h D (scaled into the band's s K, so that
    s K + m_coef M is it on them): ``system`` (:class:`derods._numba.implicit.System`);
    local_of_dof (nv,) maps MuJoCo dofs to the n + k, a0 (n + k,) [m/s^2] the rods'
    unconstrained acceleration and the trees' without constraint forces. With no trees,
    the rods' own arrays."""

    def __init__(self, m, d, system, contact: ContactStep, trees, a0):
        self.contact = contact
        n, s = system.n, system.s
        if not len(trees):
            self.n, self.local_of_dof = n, contact.local_of_dof
            self.system, self.a0 = system.arrays, a0.copy()
            self.dofs = np.zeros(0, np.int64)
            return
        dofs = tree_dofs(m, trees)
        k = len(dofs)
        metric = contact._dynamics.metric(m, d, dofs)
        rows = system.a_band.shape[0]
        band = np.zeros((rows, k))
        for dd in range(min(rows, k)):
            band[dd, :k - dd] = np.diagonal(metric, -dd)
        lt = np.zeros((k, rows))
        cholesky_into(band, lt)
        local = contact.local_of_dof.copy()
        local[dofs] = n + np.arange(k)
        zeros = np.zeros(k)
        self.n, self.local_of_dof, self.dofs, self.metric = n + k, local, dofs, metric
        self.system = system.arrays._replace(
            k_band=np.hstack([system.k_band, band / s]), a_band=np.hstack([system.a_band, band]),
            lt=np.vstack([system.lt, lt]), g=np.concatenate([system.g, zeros]), z=np.concatenate([system.z, zeros]),
            mass=np.concatenate([system.mass, zeros]))
        self.a0 = np.concatenate([a0, np.linalg.solve(metric, d.qfrc_smooth[dofs])])

    def write(self, d, qacc) -> None:
        """The appended trees' acceleration, for MuJoCo's integrator to reproduce."""
        if len(self.dofs):
            self.contact._dynamics.write(d, self.dofs, self.metric, qacc)
