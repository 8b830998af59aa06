"""The alpha mode's step: generalized-alpha (Chung and Hulbert 1993) on the implicit
mode's system, solved by Newton's method, with backward Euler's step where contacts or
held bodies are involved (its coefficients and their analysis: :mod:`derods.sim.generalized_alpha`;
its compiled solve and position update: :mod:`derods._numba.generalized_alpha`).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .._numba import generalized_alpha as _ga
from .._numba.calls import Bound
from .._numba.projection import predict_into
from ..step import evaluate
from . import generalized_alpha as ga
from .divergence import MAX_STRAIN
from .integrators import Implicit
from .projection import PROJECTION_MAX_ITER, PROJECTION_TOL

#: The alpha mode's Newton iterations per step, at most, and their tolerance [relative to
#: the shortest edge] on the change of the evaluation point x_{1-af}. Linearized once
#: (as the implicit mode is), an edge turning by phi per step is stretched by ~phi^2 / 2
#: and the stiff stretching term turns that into a drag: an undamped cantilever swinging
#: at w h = 0.18 kept 0.885 of its amplitude per period; iterating removes it.
NEWTON_ITERATIONS = 4
NEWTON_TOL = 1e-6
#: An iteration must shrink the change at least this much, or the step falls back to
#: backward Euler's (large rotations per step, where the iteration need not converge).
NEWTON_CONTRACTION = 0.5
#: After the last iteration, a change above this [relative to the shortest edge] makes the
#: step backward Euler's too.
NEWTON_ACCEPT = 1e-3


class GeneralizedAlpha(Implicit):
    """Generalized-alpha (Chung and Hulbert 1993) solved by Newton's method (up to
    NEWTON_ITERATIONS re-linearizations at the scheme's evaluation point): second order,
    no numerical damping of resolved modes, unresolved ones damped to rho_inf per step
    (:mod:`derods.sim.generalized_alpha`). A step in which a contact touches a rod, or
    Newton's iteration stalls, is backward Euler's (contacts re-solved in its metric, as
    in the implicit mode). The strain limit projects positions at the start of a step
    (the velocity change it makes is not carried in the scheme's acceleration)."""

    mode = "alpha"

    def __init__(self, *args, rho_inf: float = ga.RHO_INF, **kwargs):
        super().__init__(*args, **kwargs)
        #: Its Newton iterations take the forces at the held vertices' new places.
        self.prescribes = False
        self.coefficients = ga.Coefficients.from_rho_inf(rho_inf)
        self._alpha_step = Bound(_ga.alpha_step)  # the same bundles every step
        self.a_prev = np.zeros(self.layout.n)
        self._w = np.zeros(self.layout.n)
        self._zero = np.zeros(self.layout.n)
        self._shift = np.zeros(self.layout.n)
        self._offset = np.zeros(self.layout.n)
        self._start = True
        self._touched = False
        #: Whether the last step was backward Euler's (the first, a contact touched a
        #: rod, or Newton's iteration stalled).
        self.euler_step = False
        #: Linear solves the last step's Newton iterations made (1: converged at once).
        self.solves = 0
        #: Newton iterations on the step's nonlinear equation after the linearized solve
        #: (0: linearly implicit, as the implicit mode).
        self.newton_iterations = NEWTON_ITERATIONS
        rest = self.rods.rest_len
        self._length_scale = float(np.min(rest)) if len(rest) else 1.0

    carried_flags = Implicit.carried_flags + ("_start",)

    def carried(self) -> list[np.ndarray]:
        return super().carried() + [self.a_prev]

    def restart(self) -> None:
        """Forget the carried acceleration: the next step starts from the forces'."""
        self._start = True

    def _prepared(self, x: np.ndarray) -> np.ndarray:
        return self.positions() if self._project_positions(x) else x

    def _project_positions(self, x: np.ndarray) -> int:
        """Project the rods strained beyond the strain limit onto their rest lengths,
        moving qpos and adding the move / h to qvel. Returns how many were."""
        self.n_projected = 0
        if math.isinf(self._strain_limit_now()):
            return 0
        inv_mass = self._touching() if self.n_steps else self.inv_mass
        self._shift[:] = 0.0

        def limit(weights: np.ndarray) -> tuple[int, int]:
            return self._limit_kernel(x, self.rods.v_off, self.rods.e_off, self.rods.rest_len, weights,
                                      self.layout.place, self._zero, self._shift, 1.0, self.limited,
                                      self.strain_limit, PROJECTION_TOL, PROJECTION_MAX_ITER, self._xp, x)
        n = self._projected(limit, inv_mass)[0]
        if n:
            lay = self.layout
            qpos = (lay.qpos_adr[:, None] + np.arange(3)).ravel()
            self.qpos[qpos] += self._shift
            self.qvel[lay.dofs] += self._shift / self.h
        self.n_projected = n
        return n

    def _limit_strain(self, a: np.ndarray, inv_mass: np.ndarray | None = None,
                      held_x: np.ndarray | None = None) -> tuple[int, int]:
        if self.holders:
            # Rods held by bodies with dofs step as backward Euler's, and their strain limit
            # is its, in the coupled solve (with the holders pulled where a rod cannot reach
            # them, derods.sim.coupled); on positions, a step later, a 10 kg box swinging on a
            # world-clamped rod at dt 1e-2 was out of the rod's reach and it diverged.
            return super()._limit_strain(a, inv_mass, held_x)
        return 0, 0  # done on positions, at the start of the next step

    def _unconstrained(self, lay, t, s) -> None:
        c = self.coefficients
        self.euler_step = False
        if self._start or self.holders:
            # Rods held by bodies with dofs step as backward Euler's (the coupling of
            # derods.sim.holders is written for it).
            # The first step (and the first after a restart or a contact) is backward
            # Euler's, whose acceleration seeds the scheme's: the forces' explicit
            # acceleration in a stiff state (an edge stretched by the last Euler step) is
            # huge, and gamma a1 = qacc - (1 - gamma) a0 then throws the rod.
            self._euler()
            return
        self._offset[:] = 0.0
        self._solve(lay, t, s, c)
        fr = self.frames
        saved = fr.copy()
        last = math.inf
        self.solves = 1
        for k in range(self.newton_iterations + 1):
            change = _ga.alpha_point(self.a0, self.a_prev, self.v, c.alpha_f, c.beta, c.gamma, self.h, self._offset)
            if change <= NEWTON_TOL * self._length_scale:
                break
            if k == self.newton_iterations and change <= NEWTON_ACCEPT * self._length_scale:
                break  # close enough
            if change > NEWTON_CONTRACTION * last or k == self.newton_iterations:
                # not converging, or not in time: this step is Euler's
                fr.u[:], fr.t[:], fr.theta[:], fr.theta_end[:] = saved.u, saved.t, saved.theta, saved.theta_end
                self._euler()
                return
            last = change
            predict_into(self.x, lay.place, self._zero, self._offset, 1.0, self._xp)
            evaluate(self.rods, fr, self._xp, lay.place, t, self.ends, self.xmat, MAX_STRAIN, self._bands,
                     self._band_of_rod, self._rods_step)
            self._solve(lay, t, s, c)
            self.solves += 1
        fr.u[:], fr.t[:], fr.theta[:], fr.theta_end[:] = saved.u, saved.t, saved.theta, saved.theta_end

    def _euler(self) -> None:
        """Make this step backward Euler's: forces at x0, the implicit mode's solve (the
        strain at x0 checked when the step began: its prescribed vertices' move, forgiven
        there, is not a divergence here either)."""
        self.forces(self.x, checked=True)
        Implicit._unconstrained(self, self.layout, self.terms, self.system)  # factored with Euler's weights
        self.euler_step = True

    def _solve(self, lay, t, s, c) -> None:
        """One linearized solve about x0 + offset, into self.a0 (the unconstrained qacc)."""
        self._alpha_step(s.arrays, t, lay.places, self.params, c, self.qvel, self.xfrc_applied, self.a_prev,
                         self._offset, self.v, self.other, self._rhs, self._kv, self._w, self.a0)

    def _contact(self, d: mujoco.MjData) -> np.ndarray | None:
        if not self.euler_step and self.contact.touches(d):
            # A contact touches a rod: this step is backward Euler's, from the forces at x0,
            # and its one contact solve is Euler's. (Carried in the scheme's acceleration, a
            # contact impulse would come back in the next steps' predictors, and its position
            # response would be beta / gamma of Euler's: a rod dropped on the floor kept
            # bouncing.)
            self._euler()
        a = self.contact(d, self.system, self.a0)
        self._touched = a is not None
        return a

    def _integrated(self, a: np.ndarray) -> None:
        if self.euler_step:
            # Backward Euler's acceleration seeds the next step, unless a contact's impulse
            # is in it: then the next step is Euler's too.
            self.a_prev[:] = a
            self._start = self._touched
            return
        c = self.coefficients
        _ga.finish_step(a, self.a_prev, c.beta, c.gamma, self.h, self.layout.qpos_adr, self.qpos)
