"""The implicit step's prediction and its conclusion after the contact solve, each as one
compiled call (:class:`OneCallStages`; the kernels: :mod:`derods._numba.implicit_stages`):
where nothing must run between them, the step hands numba its bundles once instead of at
every kernel, with no Python between (which worlds: ``Implicit._in_one_call``). The same
kernels in the same order as the step's kernel-by-kernel path, so the same trajectories to
the bit (tests/test_prediction.py)."""

from __future__ import annotations

import numpy as np

from .._numba.calls import Bound
from .._numba.implicit_stages import ConcludeArrays, PredictArrays, conclude, predict
from .divergence import MAX_STRAIN
from .projection import PROJECTION_MAX_ITER, PROJECTION_TOL
from .strain_limit import TOUCHING_WEIGHT


class OneCallStages:
    """The one-call stages' part of the implicit step (:class:`derods.sim.integrators.Implicit`),
    which it reads: the step's arrays and bundles (layout, rods, frames, terms, system, ...),
    the strain limit's (inv_mass, limited, _limited_rest, _xp), contact, diagnosis."""

    def _one_call_stages(self) -> None:
        """The stages' compiled calls (at the step's construction; their arrays at the first
        step that takes them, :meth:`_stage_arrays`)."""
        # The same argument objects every step (the contact stage's a and force are its own).
        self._prediction, self._conclusion = Bound(predict), Bound(conclude)
        self._arrays: tuple[PredictArrays, ConcludeArrays] | None = None

    def _stage_arrays(self) -> tuple[PredictArrays, ConcludeArrays]:
        """The arrays the one-call stages take (:mod:`derods._numba.implicit_stages`), made
        once (again if the implicit system's bundle was replaced: a new band)."""
        if self._arrays is None or self._arrays[0].system is not self.system.arrays:
            lay, r = self.layout, self.rods
            self._arrays = (
                PredictArrays(lay.x0, self.qpos, lay.qpos_adr, lay.free_vertex, self.xpos, lay.moved_vertex,
                              lay.moved_body, self.x, r, self.ends, self.frames, self.xmat, lay.place, self._bands,
                              self._band_of_rod, self.terms, self.system.arrays, lay.places, self.params, self.qvel,
                              self.xfrc_applied, self.v, self.other, self._rhs, self._kv, self.a0, self.inv_mass,
                              self.limited, self._xp, lay.dofs, lay.mass, self.qfrc_applied),
                ConcludeArrays(self.x, r.v_off, r.e_off, r.rest_len, lay.place, self.v, self.h, self.inv_mass,
                               lay.free_vertex, np.empty_like(self.inv_mass), self._limited_rest, self._xp, lay.dofs,
                               lay.mass, self.qacc, self.qfrc_smooth, self.qfrc_constraint, bool(self.resolves)))
        return self._arrays

    def _predict(self, limit: float) -> None:
        """elastic(), unconstrained(), the strain limit on a0 and the force written for
        MuJoCo, as one compiled call (the same kernels in the same order: the same results).
        limit: the step's strain limit (StrainLimit._strain_limit_now)."""
        self.x_start = self.x
        try:
            bad, self.n_projected = self._prediction(self._stage_arrays()[0], MAX_STRAIN, limit, PROJECTION_TOL,
                                                     PROJECTION_MAX_ITER)
        except ValueError as err:  # a banded Cholesky found A (or a projection's matrix) not positive definite
            self.diagnosis.not_positive_definite(str(err), self.n_steps, self.data.time)
        if bad >= 0:
            self.diagnosis.strain(bad, float(self.terms.strain[bad]), self.n_steps, self.data.time)

    def _conclude(self, a: np.ndarray, limit: float) -> None:
        """The strain limit on the contact solve's acceleration a (n,) [m/s^2] (touching
        vertices made lighter, rods it leaves projected by their own masses) and a written
        for MuJoCo's integrator, as one compiled call (as _limit_strain(a, _touching())
        and write_acceleration: the same results). limit: as :meth:`_predict`'s."""
        try:
            self.n_projected += self._conclusion(self._stage_arrays()[1], a, self.contact.force, TOUCHING_WEIGHT,
                                                 limit, PROJECTION_TOL, PROJECTION_MAX_ITER)
        except ValueError as err:  # the projection's banded Cholesky, in a state gone wild
            self.diagnosis.not_positive_definite(str(err), self.n_steps, self.data.time)
