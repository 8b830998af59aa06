"""The DER paper's step in a MuJoCo world (``World(mode="projection")``): implicit bending
and twisting, inextensibility by fast projection (:mod:`derods.sim.projection`)."""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba import coupling as _io
from .._numba.projection import projection_step
from .integrators import Implicit
from .projection import PROJECTION_MAX_ITER, PROJECTION_TOL


class Projection(Implicit):
    """The DER paper's method: implicit bending and twisting, inextensibility by fast
    projection (:mod:`derods.sim.projection`); MuJoCo resolves contacts with the bare
    vertex masses, as in the explicit mode. Where bodies with dofs hold rods, the step is
    the implicit mode's one solve of rods, holders and contacts (:mod:`derods.sim.coupled`)
    with every open rod projected onto its rest lengths after it (a strain limit of 0):
    applied one step late, the rods' reaction made a light holder diverge."""

    mode = "projection"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        lay = self.layout
        self._accel = np.zeros(lay.n)
        if self.holders:
            self.limited = np.array([not e.rod.closed for e in self.entries], dtype=np.int8)
            self.strain_limit = 0.0

    def step(self) -> None:
        if self.holders:
            Implicit.step(self)
            return
        lay = self.layout
        self.elastic()
        self.unconstrained()
        bad = projection_step(self.x, self.rods.v_off, self.rods.e_off, self.rods.rest_len, self.inv_mass,
                              lay.place, self.v, self.a0, self.h, PROJECTION_TOL, PROJECTION_MAX_ITER, self._xp,
                              self._accel)
        if bad >= 0:
            self.diagnosis.projection(bad, PROJECTION_MAX_ITER, self.n_steps, self.data.time)
        _io.write_applied(lay.dofs, lay.mass, self._accel, self.other, self.qfrc_applied)
        mujoco.mj_step(self.model, self.data)
        self.n_steps += 1
        self.check()
