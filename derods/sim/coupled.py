"""One solve per step of the rods, the bodies that hold them, the bodies that touch
them, and every contact row among them.

Where rods are held by bodies with dofs (:mod:`derods.sim.holders`), solving the rods,
the holders and the contacts in turn, each with the others frozen, is right for each
part alone and wrong together: a rope hanging over a cylinder from two weights was
pulled through it (the contact force never reached the weights), a light box holding a
rod bounced off the floor (its contact force was MuJoCo's, computed for the bare box),
and the strain limit, run before the holders moved, projected the rod around where its
holder had been. Here all of it is one problem, MuJoCo's primal contact problem in the
metric of the coupled implicit step:

    minimize  1/2 (a - a*)^T H (a - a*) + sum_i 1/2 D_i min(J_i a - aref_i, 0)^2

over a = (a_f, a_q): a_f the rods' free dofs and the dofs of small trees their rows
touch (:class:`derods.sim.contact.ContactStep`), a_q every dof of the holders' trees.
H is the coupled step's matrix of :mod:`derods.sim.holders`,

    H = [[A, s K_fq], [s K_qf, M - h D + s K_qq]],

A banded over a_f and the holders a dense border of m dofs; a* its unconstrained
solution; the rows every supported row that touches only these dofs (a held edge on the
floor, the holder's own contacts, the rope on the cylinder). Newton's method on it
(:func:`derods._numba.contact_newton.newton` with a :class:`derods._numba.contact_newton.Border`)
solves with the band's Cholesky factor and the border's Schur complement; row weights
keep MuJoCo's impedance in this metric (D = 1 / (R / diagA * diag(J H^-1 J^T))). The
holders' trees get the acceleration found, written as the force that makes MuJoCo's
integrator reproduce it (:mod:`derods.sim.trees`), and so do the touching trees.

Four details keep it well posed. A held edge's contact with its own holder takes no
force (MuJoCo excludes a body's parent and children, but not for flex elements). The
holders' Schur complement is kept at least their inertia (:func:`definite`). The held
points move on the arcs their turning bodies take, not along the tangent J dq the linear
solve knows: the difference is a known motion of theirs in the solve
(:meth:`CoupledStep._arc`). And the strain limit runs once, after the solve, with the
held vertices where MuJoCo's integrator takes their bodies
(:meth:`CoupledStep._limit_strain`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba import contact as _k
from .._numba.calls import Bound
from .._numba.contact_newton import Border, newton
from .._numba.coupled import (BorderedRows, bordered_rows, force_into, holder_steps_into, moved_into,
                              row_forces_into, start_into)
from .._numba.dense import lu_solve, spd_factor
from .._numba.implicit import sm_solve_columns_into, sm_solve_into
from .contact import MAX_ITER, SUPPORTED, TOL, WINDOW, ContactStep, WithTrees, cones_or_none
from .held_limit import hanging_rods, pull_holders, turn_held
from .holders import Holders
from .layout import element_bodies

#: A held point's arc (:meth:`CoupledStep._arc`) guessed off by more than this share of
#: the shortest edge is solved again: the strain the miss leaves in a held edge.
ARC_TOL = 1e-5


class CoupledStep:
    """The coupled solve of a world whose rods are held by bodies with dofs.

    holders: the world's :class:`Holders` (non-empty); contact: its
    :class:`ContactStep` (for the trees that touch rods, and ``force``). After a call,
    ``contact.force`` (n,) [N] holds the constraint force on the rod dofs and
    ``held_x`` (n_vertices, 3) [m] where the held vertices will be at the end of the step.
    """

    def __init__(self, model: mujoco.MjModel, layout, holders: Holders, contact: ContactStep):
        self.model, self.layout = model, layout
        self.holders, self.contact = holders, contact
        self.m = len(holders.tree)
        self.nv = model.nv
        self.border_of_dof = np.full(model.nv, -1, dtype=np.int64)
        self.border_of_dof[holders.tree] = np.arange(self.m)
        self.is_sparse = bool(mujoco.mj_isSparse(model))
        self.held_x = layout.x0.copy()
        #: Whether a held edge collides with the body holding it (ContactParams.holder_contact);
        #: off, as MuJoCo does not collide a body with its parent or children.
        self.holder_contact = False
        self._elem_holder = _element_holders(model, layout, holders.bodies)
        self._qvel = np.zeros(model.nv)
        self._no_rows = np.zeros(0, dtype=np.bool_)
        self._no_rods = np.zeros(0, dtype=np.int64)  # far rows' diagonal by solves (row_weights)
        self._aq_last = np.zeros(self.m)
        self._dq = np.zeros(len(holders.dofs))  # the holder dofs' step [m or rad]
        # The step's unconstrained solution (see __call__): s K_fq and y = A^-1 s K_fq (n, k),
        # y0 (n,), H_qq, S and its LU factors, the holders' force; Newton's start a (n,), a_q.
        k = len(holders.dofs)
        self._sk_f, self._y, self._y0 = np.zeros((layout.n, k)), np.zeros((layout.n, k)), np.zeros(layout.n)
        self._h_qq, self._schur, self._lu = (np.zeros((self.m, self.m)) for _ in range(3))
        self._piv, self._force = np.zeros(self.m, dtype=np.int64), np.zeros(self.m)
        self._a, self._aq = np.zeros(layout.n), np.zeros(self.m)
        # Compiled calls that take the same argument objects step after step (or ones made
        # alike, see _keyed): typed once.
        self._solve_columns, self._bordered_rows = Bound(sm_solve_columns_into), Bound(bordered_rows)
        self._row_weights, self._newton, self._row_forces = Bound(_k.row_weights), Bound(newton), Bound(row_forces_into)
        self._arc_tol = ARC_TOL * holders.shortest_edge
        #: Whether the dofs that move held points are all of their trees' (a cart, a box, an arm).
        self._whole_tree = len(holders.dofs) == self.m
        #: Geoms of the holders that collide, whose contacts with a held edge are the edge's own.
        self._holder_geom = np.isin(model.geom_bodyid, holders.bodies) & (
            (model.geom_contype != 0) | (model.geom_conaffinity != 0))
        self._any_holder_geom = bool(self._holder_geom.any())
        #: The vertices riding on bodies with dofs, and their vertex bodies.
        riding = np.isin(model.body_rootid[layout.moved_body], model.body_rootid[holders.bodies])
        self._riding_vertex, self._riding_body = layout.moved_vertex[riding], layout.moved_body[riding]
        self._held_are_riding = set(self._riding_vertex.tolist()) == set(holders.held.tolist())
        #: The rods held by bodies with dofs at one end, the other free (held_limit.turn_held).
        self._hanging = hanging_rods(layout, holders)
        self._contact_types = np.array([int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS),
                                        int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
                                        int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC)])

    def __call__(self, step) -> np.ndarray:
        """The rods' acceleration [m/s^2] (n,) of this step; the holders' and touching
        trees' qacc and constraint forces are written into MuJoCo's data."""
        m, d, hl, sysm, lay = step.model, step.data, self.holders, step.system, step.layout
        h, b = step.h, step.stiffness_damping
        s = h * h + h * b
        n, mq, c = lay.n, self.m, hl._in_tree
        stiff = hl.stiffness_columns(step)
        k_f, k_q = stiff.k_f, stiff.k_q
        metric = hl._dynamics.metric(m, d, hl.tree)
        h_qq = self._h_qq
        if self._whole_tree:
            np.add(metric, s * k_q, out=h_qq)
        else:
            h_qq[:] = metric
            h_qq[np.ix_(c, c)] += s * k_q  # the held-dof block of the tree's
        # The rods' system, extended by the trees the rows bind to rods this step.
        # (a tree too large for the band keeps MuJoCo's forces here: not yet a second border)
        trees = (self.contact.small_trees(self.contact._touching_trees(d)) if (self.contact.bodies and d.nefc)
                 else np.zeros(0, np.int64))
        self.contact.joined_trees = np.union1d(trees, hl.trees).astype(np.int64)  # the holders' trees always join
        ext_sys = WithTrees(m, d, sysm, self.contact, trees, step.a0)
        nn = ext_sys.n
        # Without touching trees, the compiled calls get the same objects every step, or ones
        # made alike (see _keyed); with them, the system and the dof maps are made afresh.
        plain = nn == n and self._whole_tree
        own = self._own_holder_rows(d) if d.nefc else None  # neither solved nor MuJoCo's: no force at all
        rows = self._rows(d, ext_sys, own) if d.nefc else None
        ext, ext_q = (rows.ext, rows.ext_q) if rows is not None else (np.zeros(nn), np.zeros(mq))
        start = ext_sys.a0.copy()
        if ext.any():
            e = ext.copy()
            sm_solve_into(ext_sys.system, e)
            start += e
        # The coupled unconstrained solution a* (holders.py's Schur complement on A): numpy's
        # products, the rest compiled (derods._numba.coupled).
        v_q = step.qvel[hl.dofs]
        sk_f, y = self._sk_f, self._y
        np.multiply(s, k_f, out=sk_f)
        y[:] = sk_f
        self._solve_columns(sysm.arrays, y)  # A^-1 s K_fq, (n, k)
        y0, schur, force, lu, piv = self._y0, self._schur, self._force, self._lu, self._piv
        start_into(start, y @ v_q, (b + h) / s, h_qq, k_f.T @ y, s, c, y0, schur)
        # (slide-only holders have the Gauss-Newton K_qq = J^T K_hh J: S >= M by construction)
        fix = definite(schur, metric) if hl.turning else None
        if fix is not None:
            schur += fix
            h_qq += fix
        force_into(step.qfrc_smooth, hl.tree, ext_q, c, b + h, k_f.T @ step.v, k_q @ v_q, s, k_f.T @ y0, schur,
                   force, lu, piv)  # and S's factors, for every solve below
        solving = rows is not None and len(rows.efc) > 0
        if solving:
            if plain:  # no touching trees; the held dofs are the trees'
                h_fq, big_y = sk_f, y
            else:
                h_fq = np.zeros((nn, mq))
                h_fq[:n, c] = sk_f
                big_y = np.zeros((nn, mq))
                big_y[:n, c] = y
            # MuJoCo's impedance kept in this metric (see the module docstring)
            weights = self._keyed(self._row_weights, plain, (ext_sys.system, d, y, lu, piv),
                                  ext_sys.system, rows.rows, big_y, rows.jq, lu, piv, rows.ratio, self._no_rods,
                                  rows.cones)

        def solve(arc=None):
            """a, a_q and the rows' multipliers (None: no rows) with the held points moved
            ``arc`` (3H,) [m] beyond J dq (None: not at all): the unconstrained solution, then
            the contact Newton from it (started from the step's buffers: a_q, and a without
            touching trees, whose a[:n] is all of it)."""
            f_q, a = self._aq, self._a if nn == n else start.copy()
            f_q[:] = force
            if arc is None:
                lu_solve(lu, piv, f_q)
                a[:n] = y0 - y @ f_q[c]
            else:
                y_arc = sysm.solve(stiff.k_fh @ arc)
                f_q[c] -= stiff.jac.T @ (stiff.k_hh @ arc) - s * (k_f.T @ y_arc)
                lu_solve(lu, piv, f_q)
                a[:n] = y0 - y_arc - y @ f_q[c]
            if not solving:
                return a.copy(), f_q.copy(), None  # (the buffers are the next solve's)
            a, aq, lam, _ = self._keyed(self._newton, plain, (ext_sys.system, d, a, h_fq, h_qq, f_q),
                                        ext_sys.system, a, rows.rows, rows.aref, weights,
                                        Border(h_fq, h_qq, rows.jq, f_q), cones_or_none(rows.cones), MAX_ITER,
                                        TOL)
            return a, aq, lam

        if not hl.turning:  # held points only translate: no arcs
            a, aq, lam = solve()
        else:
            # The held points move on arcs (see _arc), known once a_q is: guessed from the
            # last step's a_q and solved, then solved again with the arc of that solution if
            # the guess missed it by more than ARC_TOL of an edge. (A guess that missed by
            # more than a tenth of the arc itself was left out until 2026-12-05, against a
            # 1 g box tumbling as it landed; a light arm whose a_q alternates from step to
            # step then moved its held point on the tangent every other step, its rod's
            # first edge stretched 1.3e-4 each time. Measured with the arc kept: the held
            # sweep's 50 landings, boxes of 1 g to 10 t at dt 1e-3 to 1e-2, all right.)
            arc = self._arc(step, stiff.jac, self._aq_last)
            a, aq, lam = solve(arc)
            again = self._arc(step, stiff.jac, aq)
            if np.max(np.abs(again - arc), initial=0.0) > self._arc_tol:
                a, aq, lam = solve(again)
            self._aq_last[:] = aq
        if solving:  # and derods' row forces where MuJoCo's readers look (a held edge's on its holder: none)
            self._row_forces.keyed((d, self.contact.force), (rows, lam, self.contact.force, d.efc_force))
            if own is not None:
                d.efc_force[:d.nefc][own] = 0.0
        elif ext.any():
            self.contact.force[:] = ext[:n]
        else:
            self.contact.force[:] = 0.0
        af = a[:n]
        self._limit_strain(step, af, aq, stiff.jac, metric, contact_free=not solving)
        hl._dynamics.write(d, hl.tree, metric, aq)
        ext_sys.write(d, a[n:])
        return af

    def _rows(self, d: mujoco.MjData, ext_sys: WithTrees, own: np.ndarray | None) -> BorderedRows:
        """MuJoCo's rows of this step split for the solve over the rods' dofs (and the
        touching trees', ext_sys) bordered by the holders' (:func:`bordered_rows`)."""
        rest = (SUPPORTED, self._no_rows if own is None else own, ext_sys.local_of_dof, self.border_of_dof,
                ext_sys.n, self.m, WINDOW)
        efc, cones = self.contact.rows(d), self.contact.cone_contacts(d)
        if own is None and ext_sys.n == self.layout.n:  # the rest: the same objects every step
            return self._bordered_rows.keyed((d, d if self.contact.elliptic else cones) + rest, (efc, cones) + rest)
        return self._bordered_rows.kernel(efc, cones, *rest)

    @staticmethod
    def _keyed(bound: Bound, plain: bool, key: tuple, *args):
        """``bound``'s kernel on args, its compiled function remembered for the key's objects
        when ``plain`` (:meth:`derods._numba.calls.Bound.keyed`). The key holds the step's
        system and buffers (the same objects every step) and MuJoCo's data, which stands for
        the arguments made afresh each step from its rows: :func:`bordered_rows`' bundle,
        the row weights and Newton's results, arrays that compiled code allocates (C-ordered,
        of the dtypes its code fixes), so of one type whatever the step."""
        if plain:
            return bound.keyed(key, args)
        return bound.kernel(*args)

    def _limit_strain(self, step, af: np.ndarray, aq: np.ndarray, jac: np.ndarray, metric: np.ndarray,
                      contact_free: bool) -> None:
        """The strain limit (:data:`derods.sim.strain_limit.STRAIN_LIMIT`) on the coupled
        solution af (n,) [m/s^2] (changed in place), the vertices held by bodies with dofs
        predicted exactly where MuJoCo's integrator takes them with aq (m,) and kept
        there: the projection moves the free vertices only, as for rods held by the
        world. (Predicted to first order, J (v_q + h a_q), a box spinning at 24 rad/s at
        dt 1e-2 put its held point 0.6 mm off its arc, the rod's first edge 4.6 % too
        long, and the box diverged; moving the held points by their holders' inertia
        instead, without their contacts, did not help either.) jac (3H, k): the held
        points' Jacobian: where no held point turns, they move by it exactly; metric (m, m):
        the holders' M - h D. A rod the held points leave out of reach is projected again
        with them pulled (:func:`derods.sim.held_limit.pull_holders`), aq (changed in place)
        with them. In a step without contact rows (``contact_free``), rods held at one end
        have their turning edges brought to their first-order lengths with their holders
        moving (:func:`derods.sim.held_limit.turn_held`)."""
        hl = self.holders
        if not hl.turning and self._held_are_riding:
            holder_steps_into(step.qvel, hl.dofs, aq, hl._in_tree, step.h, self._dq)
            moved_into(step.x, hl.held, jac @ self._dq, self.held_x)
        else:
            self.held_x[:] = step.x
            if len(self._riding_vertex):
                self._predict_held(step, aq)
        step.n_projected, left = step._limit_strain(af, step._touching(), self.held_x)
        if left:
            step.n_projected += pull_holders(step, self.holders, self.held_x, af, aq, jac, metric)
        if contact_free and len(self._hanging):
            step.n_projected += turn_held(step, self.holders, self._hanging, self.held_x, af, aq, jac, metric)

    def _predict_held(self, step, aq: np.ndarray) -> None:
        """held_x of the vertices held by bodies with dofs: where MuJoCo's integrator takes
        them with the holders' acceleration aq (m,) (:meth:`_integrated`: a turning
        holder's points move on arcs)."""
        self.held_x[self._riding_vertex] = self._integrated(step, aq).xpos[self._riding_body]

    def _integrated(self, step, aq: np.ndarray) -> mujoco.MjData:
        """The scratch copy of MuJoCo's data posed where its integrator takes the holders'
        trees this step with acceleration aq (m,): qvel + h aq, mj_integratePos, kinematics
        (mocap poses copied: a jointed body may hang from a mocap one). Its velocity is left
        in ``self._qvel``."""
        m, d, hl, h = step.model, step.data, self.holders, step.h
        ds = hl._scratch
        ds.qpos[:] = d.qpos
        ds.mocap_pos[:], ds.mocap_quat[:] = d.mocap_pos, d.mocap_quat
        self._qvel[:] = 0.0
        self._qvel[hl.tree] = d.qvel[hl.tree] + h * aq
        mujoco.mj_integratePos(m, ds.qpos, self._qvel, h)
        mujoco.mj_kinematics(m, ds)
        return ds

    def _arc(self, step, jac: np.ndarray, aq_guess: np.ndarray) -> np.ndarray:
        """How far beyond J h v the held points go in this step [m], shape (3H,), their
        holders' velocity becoming v = qvel + h aq_guess (m,): x(q + h v) - x(q) - J h v,
        with MuJoCo's integrator and kinematics on a scratch copy (jac (3H, k): J).

        The coupled step is linear in the holders' motion, so it moves a held point along
        its arc's tangent; MuJoCo's integrator takes it along the arc, 1/2 (h w)^2 R inward
        (a hinge at w rad/s, the point R from its axis). A rod's stiff first edge, moved
        with the tangent, comes out stretched by that over its length l each step
        (measured: 3e-4 at the first step of a rod on a 0.1 m arm at dt 1e-2, l = 4 mm;
        growing as w^2 until the strain limit projected the rod every step and a stiff
        rod's swing diverged). With the offset a known motion of the held points, the
        rods follow the arc."""
        hl = self.holders
        moved = self._integrated(step, aq_guess).xpos[hl.held_body] - step.x[hl.held]
        return moved.ravel() - jac @ (step.h * self._qvel[hl.dofs])

    def _own_holder_rows(self, d: mujoco.MjData) -> np.ndarray | None:
        """Which constraint rows (nefc,) are contacts of a held edge with its own holder's
        geoms (None: none, or holder_contact is on)."""
        if self.holder_contact or d.ncon == 0 or self._elem_holder is None or not self._any_holder_geom:
            return None
        m, con = self.model, d.contact
        geom = con.geom
        if not (self._holder_geom[geom] & (geom >= 0)).any():
            return None
        own = np.zeros(d.ncon, dtype=bool)
        for side in (0, 1):
            g, f, e = con.geom[:, side], con.flex[:, 1 - side], con.elem[:, 1 - side]
            ok = (g >= 0) & (f >= 0)
            if not ok.any():
                continue
            body = m.geom_bodyid[np.where(ok, g, 0)]
            holder = self._elem_holder[np.where(ok, m.flex_elemadr[np.where(ok, f, 0)] + e, 0)]
            own |= ok & ((holder[:, 0] == body) | (holder[:, 1] == body))
        if not own.any():
            return None
        rows = np.isin(d.efc_type[:d.nefc], self._contact_types)
        rows[rows] = own[d.efc_id[:d.nefc][rows]]
        return rows


def definite(schur: np.ndarray, metric: np.ndarray) -> np.ndarray | None:
    """The smallest symmetric correction that makes the holders' Schur complement S
    (m, m) at least their metric M - h D (m, m) in every direction, or None if it is.

    The rods' band is the Gauss-Newton part of their Hessian (positive semidefinite), but
    K_qq comes from differencing the rods' reaction: exact, with the geometric stiffness
    of the force they carry (a rod pushing on a box's edge turns it). Where that is
    negative and the holder light, the coupled matrix is indefinite (measured: a 10 g box
    holding a rod that lands on the floor at dt 1e-2, S's smallest eigenvalue relative to
    M went 1, 0.42, -0.61 and the step diverged). The Gauss-Newton model has S >= M (the
    rods' stiffness as the holders feel it, a Schur complement of a PSD matrix, adds to
    their inertia), so the generalized eigenvalues of (S, M) below 1 are raised to 1."""
    sym = 0.5 * (schur + schur.T)
    if spd_factor(sym - (1.0 - 1e-9) * metric):  # S - M >= 0 but for round-off (a rigid mode): nothing to do
        return None
    chol = np.linalg.cholesky(metric)
    t = np.linalg.solve(chol, np.linalg.solve(chol, sym).T)
    lam, vec = np.linalg.eigh(0.5 * (t + t.T))
    if lam.min() >= 1.0:
        return None
    lift = chol @ vec
    return (lift * (np.maximum(lam, 1.0) - lam)) @ lift.T


def _element_holders(model: mujoco.MjModel, layout, bodies: np.ndarray) -> np.ndarray | None:
    """For every flex element of the model, the ``bodies`` (holders with dofs; up to 2, -1
    for none) that hold one of its vertices, riding it as their child, shape
    (nflexelem, 2); None if no vertex is."""
    riding = np.isin(model.body_parentid[layout.moved_body], bodies)
    if not riding.any():
        return None
    holder_of = np.full(model.nbody, -1, dtype=np.int64)  # each riding vertex body's holder
    holder_of[layout.moved_body[riding]] = model.body_parentid[layout.moved_body[riding]]
    elem = element_bodies(model)
    return np.where(elem >= 0, holder_of[np.maximum(elem, 0)], -1)
