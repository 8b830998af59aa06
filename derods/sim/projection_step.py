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
    with every open rod held to its strain limit after it (World's ``strain_limit``, 1e-3 by
    default, :data:`derods.sim.strain_limit.STRAIN_LIMIT`): applied one step late, the rods'
    reaction made a light holder diverge; and projected onto its rest lengths exactly (a
    strain limit of 0), with the held points where the solve put them, a rod gave energy to
    a light holder (a 0.1 kg arm's swing at dt 1e-3 gained 3.2 % of the energy it releases,
    a 10 g box hanging on a span rose 1.5 mm: benchmarks/bench_held.py --mode projection)."""

    mode = "projection"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        lay = self.layout
        self._accel = np.zeros(lay.n)
        if self.holders:
            self.limited = np.array([not e.rod.closed for e in self.entries], dtype=np.int8)

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
