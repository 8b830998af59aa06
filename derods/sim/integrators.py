"""One step of a world, per mode: explicit and implicit with contact (the alpha and
projection modes, built on the implicit one, are :mod:`derods.sim.alpha_step` and
:mod:`derods.sim.projection_step`).

Every mode runs the same first half (:meth:`Step.elastic`), each quantity
computed once, for all rods at once:

1. positions of every vertex from MuJoCo's qpos (and xpos for vertices held by
   moving bodies) and the strain check;
2. frames transported, clamps turned with their bodies, twist solved, forces
   and the PSD band of every rod (:func:`derods.step.evaluate`, one compiled
   call, whatever the rods' kinds and sizes);
3. the rods' reaction on the bodies that hold them.

Then the mode's own half: the explicit step applies the elastic force; the
implicit step solves the linearly implicit system (:mod:`derods.sim.implicit`),
lets MuJoCo's forward pass find the contacts, re-solves them in the implicit
metric (:mod:`derods.sim.contact`), limits the strain it leaves
(:mod:`derods.sim.strain_limit`) and lets MuJoCo integrate. Last, the
divergence check (:mod:`derods.sim.divergence`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba import coupling as _io
from .._numba import implicit as _imp
from .._numba import parallel
from .._numba import step as _rods
from .._numba.projection import limit_chunk, limit_strain
from ..step import EndBodies, Frames, RodSet, Terms, evaluate
from .clamps import Reactions
from .contact import SUPPORTED, ContactStep
from .contact_reference import ReferenceCorrection
from .implicit_stages import OneCallStages
from .coupled import CoupledStep
from .forward import Forward
from .friction import StaticFriction
from .divergence import MAX_SPEED, MAX_STRAIN, Diagnosis
from .holders import Holders
from .implicit import ImplicitSystem
from .layout import Layout, RodEntry
from .prescribed import PrescribedVertices
from .strain_limit import StrainLimit



class Step:
    """What every mode shares; ``step()`` is the mode's. Built once at compile.

    model, data: MuJoCo's. layout: :class:`derods.sim.layout.Layout`. entries: the rods.
    rods, frames, ends: the compiled step's :class:`derods.step.RodSet`, state and clamps on
    bodies. mass_damping a [1/s], stiffness_damping b [s]. diagnosis: names failures.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, layout: Layout, entries: list[RodEntry],
                 rods: RodSet, frames: Frames, ends: EndBodies, mass_damping: float, stiffness_damping: float,
                 diagnosis: Diagnosis):
        self.model, self.data = model, data
        self.layout, self.entries = layout, entries
        self.rods, self.frames, self.ends = rods, frames, ends
        self.mass_damping, self.stiffness_damping = mass_damping, stiffness_damping
        self.diagnosis = diagnosis
        self.h = float(model.opt.timestep)
        # MuJoCo's arrays, as views kept for the data's life.
        self.qpos, self.qvel, self.qacc = data.qpos, data.qvel, data.qacc
        self.xpos, self.xmat = data.xpos, data.xmat
        self.qfrc_applied, self.xfrc_applied = data.qfrc_applied, data.xfrc_applied
        self.qfrc_smooth, self.qfrc_constraint = data.qfrc_smooth, data.qfrc_constraint
        self.warnings = data.warning.number
        self.gravity = np.array(model.opt.gravity, dtype=float)
        self.params = _imp.StepParams(self.h, mass_damping, stiffness_damping, self.gravity)
        n = layout.n
        self.x = np.zeros_like(layout.x0)
        self.positions()  # where the rods start (World.rod_state before the first step reads it)
        self.terms = Terms.empty(rods.n_rods, rods.n_vertices, n, layout.band_rows)
        tw = [i for i in range(rods.n_rods) if rods.kind[i] == 1 and rods.has_twist[i] and rods.clamped[i]]
        self.rod_tw = np.array(tw, dtype=np.int64)
        # One chunk, no threads, for a world too small to gain from them.
        self.use_split(parallel.plan(rods.v_off, layout.dof_off, self.rod_tw))
        self.system = ImplicitSystem(self.h, n, layout.mass, mass_damping, stiffness_damping, layout.band_rows,
                                     layout.dof_off[self.rod_tw], layout.dof_off[self.rod_tw + 1], self.rod_tw)
        self.system.k_band = self.terms.band  # the compiled step writes K's band in place
        self._bands, self._band_of_rod = self.terms.band[None], np.zeros(rods.n_rods, dtype=np.int64)
        self.v = np.zeros(n)
        self.other = np.zeros(n)
        self.a0 = np.zeros(n)
        self._rhs = np.zeros(n)
        self._kv = np.zeros(n)
        self.reactions = Reactions(model, layout, entries, rods.e_off)
        #: Bodies riding on rod ends (derods.sim.riders), posed once the frames are known.
        self.riders = None
        self._moving = len(layout.moved_vertex) > 0
        #: Held vertices the user moves between steps (mocap bodies): their edges' strain
        #: at the step's start is the user's, not a divergence (derods.sim.prescribed).
        self.prescribed = PrescribedVertices(model, layout, rods, self.rod_tw)
        #: The positions the step starts from (self.x, or where the last step ended if the
        #: prescribed vertices moved since and the mode takes their move in the step).
        self.x_start = self.x
        self._badqacc = int(self.warnings[mujoco.mjtWarning.mjWARN_BADQACC])
        self.n_steps = 0

    def use_split(self, split: parallel.Split) -> None:
        """Step the rods in the chunks of ``split`` (:class:`derods._numba.parallel.Split`,
        over this world's rods), one a thread. The results are the same either way; the
        world's compile chose by its size (:func:`derods._numba.parallel.plan`), and tests
        and benchmarks change it to compare."""
        self.split = split
        self._rods_step = parallel.kernel(_rods.rods_step, _rods.rods_chunk, split, combine=parallel.first_bad)
        self._unconstrained_step = parallel.kernel(_imp.unconstrained_step, _imp.unconstrained_chunk, split,
                                                   bundle=True)
        # The strain limit's second call of a step takes arrays made afresh (the contact
        # solve's accelerations, the touching vertices' masses): numba's dispatcher types them.
        self._limit_kernel = parallel.kernel(limit_strain, limit_chunk, split, combine=parallel.totals,
                                             resolve=False)

    # -- the shared half ---------------------------------------------------------
    def positions(self) -> np.ndarray:
        """Every vertex's position [m] now, shape (n_vertices, 3) (into self.x)."""
        lay = self.layout
        _io.gather_positions(lay.x0, self.qpos, lay.qpos_adr, lay.free_vertex, self.xpos, lay.moved_vertex,
                             lay.moved_body, self.x)
        return self.x

    def elastic(self) -> None:
        """Positions, strain check, frames, twist, forces and band of every rod, reactions."""
        if self._moving:
            mujoco.mj_kinematics(self.model, self.data)  # after mj_step, xpos shows the previous state
            if self.reactions:
                # ... and so do the com positions and cdof mj_applyFT's Jacobian reads: left so,
                # the rods' reaction turned a holder about where its tree's centre of mass was
                # a step ago, a moment of F x (h v) that pumped a clamping body's pitch (a free
                # 0.1 kg body clamping a taut rod: pitch rate x1.5 a step at dt 1e-2)
                mujoco.mj_comPos(self.model, self.data)
        self.forces(self._prepared(self.positions()))

    def _prepared(self, x: np.ndarray) -> np.ndarray:
        """The positions x (n_vertices, 3) [m] the forces are taken at: as they are, but
        in a mode that moves them first (generalized-alpha's strain limit)."""
        return x

    #: Whether the mode takes prescribed vertices' moves in its step (derods.sim.prescribed);
    #: else it takes the forces where the user put them.
    prescribes = False

    def forces(self, x: np.ndarray, checked: bool = False) -> None:
        """Frames, twist, forces and band of every rod at positions x (n_vertices, 3) [m],
        the strain check (not again if ``checked``: x is where this step's was), and the
        rods' reactions on their holders."""
        self.x_start = x
        if self.prescribes and self.prescribed.moved(x):
            bad, self.x_start = self.prescribed.evaluate(self, x)
        else:
            bad = self._evaluate(x)
            if checked:
                bad = -1  # this step's check passed at this x (a prescribed vertex's move forgiven)
            elif bad >= 0 and self.prescribed:
                bad = self.prescribed.strained(x, self.terms.strain, MAX_STRAIN)
        if self.prescribed:
            self.prescribed.remember(x)
        if bad >= 0:
            self.diagnosis.strain(bad, float(self.terms.strain[bad]), self.n_steps, self.data.time)
        if self.reactions:
            self.reactions.apply(self.model, self.data, x, self.terms.grad, self.frames.t, self.terms.end_moment)
        if self.riders:
            self.riders(x, self.frames, self.data)

    def _evaluate(self, x: np.ndarray) -> int:
        """Frames, twist, forces and the world's band at x (one compiled call); the index of
        a rod strained beyond MAX_STRAIN, else -1."""
        return evaluate(self.rods, self.frames, x, self.layout.place, self.terms, self.ends, self.xmat, MAX_STRAIN,
                        self._bands, self._band_of_rod, self._rods_step)

    def check(self) -> None:
        """Divergence after the step: MuJoCo's bad-acceleration reset, NaN, runaway speed."""
        n_bad = int(self.warnings[mujoco.mjtWarning.mjWARN_BADQACC])
        if n_bad != self._badqacc:
            self._badqacc = n_bad
            self.diagnosis.badqacc(self.n_steps, self.data.time)
        k = _io.fastest_dof(self.qvel, self.layout.dofs, MAX_SPEED)
        if k >= 0:
            self.diagnosis.speed(self.layout.rod_of_dof(k), float(self.qvel[self.layout.dofs[k]]), self.n_steps,
                                 self.data.time)

    def unconstrained(self) -> None:
        """The implicit step without contact: factor A, solve for a0 (into self.a0)."""
        lay, t, s = self.layout, self.terms, self.system
        try:
            self._unconstrained(lay, t, s)
        except ValueError as err:  # the banded Cholesky found A not positive definite
            self.diagnosis.not_positive_definite(str(err), self.n_steps, self.data.time)

    def _unconstrained(self, lay, t, s) -> None:
        self._unconstrained_step(s.arrays, t, lay.places, self.params, self.qvel, self.xfrc_applied, self.v,
                                 self.other, self._rhs, self._kv, self.a0)

    def carried(self) -> list[np.ndarray]:
        """The arrays this mode carries from one step to the next (beside MuJoCo's state),
        which a failed step is undone to (:class:`derods.sim.divergence.Guard`)."""
        fr = self.frames
        out = [fr.u, fr.t, fr.theta]
        if self._moving:
            out.append(fr.theta_end)  # clamps on moving bodies
        if self.prescribed:
            out.append(self.prescribed.before)
        if self.reactions:
            # What the rods put on their holders: added to qfrc_applied, the last step's removed.
            out += [self.reactions._applied, self.qfrc_applied]
        return out

    #: Flags the mode carries from one step to the next, saved with ``carried()``.
    carried_flags: tuple[str, ...] = ()

    def restart(self) -> None:
        """The rods' state was set from outside (World.set_positions, set_velocities):
        forget what the mode carries between steps (nothing, but for generalized-alpha)."""

    def step(self) -> None:  # pragma: no cover - every mode has its own
        raise NotImplementedError


class Explicit(Step):
    """Apply the elastic force (and damping) and let MuJoCo integrate: stable only below
    the explicit limit (~1e-5 s for stiff rods), kept for comparison."""

    mode = "explicit"

    def step(self) -> None:
        self.elastic()
        lay, t, s = self.layout, self.terms, self.system
        _imp.explicit_force(s.arrays, t, lay.places, self.params, self.qvel, self.v, self._kv, self.qfrc_applied)
        mujoco.mj_step(self.model, self.data)
        self.n_steps += 1
        self.check()


class Implicit(OneCallStages, StrainLimit, Step):
    """Linearly implicit backward Euler with contacts re-solved in its metric (the default)."""

    mode = "implicit"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        #: Held vertices whose holders have dofs, coupled implicitly (derods.sim.holders).
        self.holders = Holders(self.model, self.layout, self.rods, self.layout.band_rows, self.reactions)
        self.contact = ContactStep(self.model, self.layout.local_of_dof, self.layout.dof_off, self.layout.n,
                                   self.layout.band_rows, self.holders.trees)
        self.coupled = CoupledStep(self.model, self.layout, self.holders, self.contact) if self.holders else None
        self.prescribes = not self.holders and self.prescribed.in_step
        #: MuJoCo's forward pass, its constraint solver skipped where derods solves every row:
        #: rows on the rods' dofs, and on their holders' trees (solved with them).
        solved = self.layout.local_of_dof >= 0
        solved[self.holders.tree] = True
        self.forward = Forward(self.model, solved, SUPPORTED)
        #: Each rod's flex (its contact settings in MuJoCo's model), shape (n_rods,).
        self.rod_flex = np.array([mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_FLEX, e.name)
                                  for e in self.entries], dtype=np.int64)
        margin = bool(np.any(self.model.flex_margin[self.rod_flex] > 0))
        self.reference = ReferenceCorrection(self.model, self.data, margin)
        #: Margins sized by the rods' speed each step (derods.sim.speculative), if asked for.
        self.speculative = None
        self.friction = StaticFriction(self.model)
        self.euler = self.model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
        # Whether MuJoCo's integrator takes qacc from the forces again: the implicit ones
        # always, Euler's when any dof is damped (it solves (M + h B) qacc = f then), so the
        # rod dofs' acceleration must be written as a force too.
        eulerdamp = not self.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
        self.resolves = not self.euler or (eulerdamp and bool(np.any(self.model.dof_damping > 0)))
        self._limits_strain()
        self._one_call_stages()

    def step(self) -> None:
        m, d, lay = self.model, self.data, self.layout
        one_call = self._in_one_call()
        if one_call:
            limit = self._strain_limit_now()
            self._predict(limit)
        else:
            self.elastic()
            self.unconstrained()
            if not self.holders:
                self.n_projected = self._limit_strain(self.a0)[0]
            # With this force MuJoCo's unconstrained acceleration of the rod dofs is a0, so its
            # own constraint solve (for bodies the rods touch) sees the implicit motion.
            _io.write_applied(lay.dofs, lay.mass, self.a0, self.other, self.qfrc_applied)
        mujoco.mj_checkPos(m, d)
        mujoco.mj_checkVel(m, d)
        if self.speculative is not None:
            self.reference.margin = self.speculative.update(self.v, self.a0)
        if self.reference:
            self.reference.update(d)
        self.forward(d)
        if self.reference:
            self.reference.correct(d)
        if self.friction:
            self.friction.anchor(d)
        concluded = False
        if self.holders:
            # Rods, holders, touching bodies and their contacts in one solve, and the strain
            # limit with the held vertices where their bodies take them (derods.sim.coupled).
            a = self.coupled(self)
        else:
            a = self._contact(d)
            if a is not None and one_call and not self.friction:
                self._conclude(a, limit)  # what follows, the acceleration written too, in one call
                concluded = True
            elif a is not None:
                # Contact impulses turn edges too: limit the strain they leave, moving only
                # the vertices no contact pushes on.
                self.n_projected += self._limit_strain(a, self._touching())[0]
        if self.friction:
            self.friction.slipped(d)
        if a is not None or self.holders:
            if not concluded:
                _io.write_acceleration(lay.dofs, lay.mass, self.a0 if a is None else a, self.qacc, self.qfrc_smooth,
                                       self.qfrc_constraint, self.resolves)
            self.forward.sensors_after(d)  # touch and force sensors read what derods applied
        mujoco.mj_checkAcc(m, d)
        if self.euler:
            mujoco.mj_Euler(m, d)
        else:
            mujoco.mj_implicit(m, d)
        self._integrated(self.a0 if a is None else a)
        self.n_steps += 1
        self.check()

    def _in_one_call(self) -> bool:
        """Whether this step's prediction (positions, terms, a0, strain limit, the force
        handed to MuJoCo) and, after the contact solve, its conclusion (strain limit,
        acceleration handed to MuJoCo) are each one compiled call
        (:class:`derods.sim.implicit_stages.OneCallStages`): in this mode, when nothing must run between
        their kernels (held vertices on moving bodies, reactions on holders, riders,
        prescribed vertices, holders with dofs) and the rods are one chunk (no threads)."""
        return (type(self) is Implicit and not self.split.parallel
                and not (self._moving or self.reactions or self.riders or self.prescribed or self.holders))

    #: The static friction's anchors are carried from step to step (see Step.carried_flags).
    carried_flags = ("friction_state",)

    @property
    def friction_state(self):
        """The anchors of the rods' sticking contacts (:class:`derods._numba.friction.Anchors`)."""
        return self.friction.state

    @friction_state.setter
    def friction_state(self, state) -> None:
        self.friction.state = state

    def _evaluate(self, x: np.ndarray) -> int:
        if self.holders and self.holders.shares_band:  # one evaluation for both bands
            return self.holders.evaluate(self, x, MAX_STRAIN)
        return super()._evaluate(x)

    def _contact(self, d: mujoco.MjData) -> np.ndarray | None:
        """The step's acceleration with contacts re-solved in its metric (None: no
        contact touches a rod, a0 stands)."""
        return self.contact(d, self.system, self.a0)

    def _integrated(self, a: np.ndarray) -> None:
        """After MuJoCo's integration with the rod dofs' acceleration a (n,): nothing more
        for backward Euler."""

    @property
    def contact_force(self) -> np.ndarray:
        return self.contact.force

