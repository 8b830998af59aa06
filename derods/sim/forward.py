"""MuJoCo's forward pass in its stages, without the constraint solver when derods solves
every constraint row itself.

In the implicit and alpha modes (and wherever rods are held by bodies with dofs) derods
re-solves each contact row that touches only rod dofs and the dofs of their holders' trees,
in the metric of its implicit step (:mod:`derods.sim.contact`, :mod:`derods.sim.coupled`),
and discards MuJoCo's answer for it. Where every row of the step is such a row (rods lying
on or hitting static and mocap geometry, touching each other or themselves, a cart's cable
on the floor), MuJoCo's constraint solver (``mj_fwdConstraint``: 24 of 37 us of
``mj_forward`` for a 32-vertex rod lying on a floor) computes nothing that is used.
:class:`Forward` runs the position stage itself; where a row is not derods' the rest is
``mj_forwardSkip`` (the same calls in the same order as ``mj_forward``: bit-identical), and
where every row is, the other stages one by one without the solver, leaving what it would
leave for dofs without rows, ``qacc = qacc_smooth`` and no constraint force; derods' solve
then writes the acceleration of the rods and their holders as before.

Either way derods' contact solve then writes its own row forces into ``efc_force`` (where
``mj_contactForce`` and the viewer read them: :mod:`derods._numba.contact`,
:mod:`derods.sim.coupled`), and the acceleration-stage sensors (touch, force, torque,
accelerometer, ...), which MuJoCo computes inside its forward pass, before derods' solve, are
computed again after it (:meth:`Forward.sensors_after`): they read what derods applied.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba.calls import Bound
from .._numba.solved_rows import rods_solve_all


class Forward:
    """``mj_forward`` for one world's step (built once at compile).

    solved_dof (nv,) bool: the dofs whose constraint rows derods solves (the rods', and
    the trees of the bodies holding them, :mod:`derods.sim.coupled`); supported: the
    constraint types its contact solve takes (``derods.sim.contact.SUPPORTED``).
    """

    def __init__(self, model: mujoco.MjModel, solved_dof: np.ndarray, supported: np.ndarray):
        self.model = model
        self.solved_dof = np.ascontiguousarray(solved_dof, dtype=np.bool_)
        self.supported = np.ascontiguousarray(supported, dtype=np.int32)
        self.is_sparse = bool(mujoco.mj_isSparse(model))
        #: Whether the model has acceleration-stage sensors (computed again after derods' solve).
        self.acc_sensors = bool(np.any(model.sensor_needstage == int(mujoco.mjtStage.mjSTAGE_ACC)))
        #: False runs mj_forward as it is (the constraint solver never skipped).
        self.enabled = True
        self.energy = bool(model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_ENERGY)
        self.sensors = model.nsensor > 0
        #: Whether the last call skipped MuJoCo's constraint solver.
        self.skipped = False
        #: Contacts the world excludes after MuJoCo's collision (:mod:`derods.sim.exclusion`).
        self.exclusions = None
        self._solve_all = Bound(rods_solve_all)  # its rows, views of the data: keyed by it

    def __call__(self, d: mujoco.MjData) -> None:
        """MuJoCo's forward pass on d, its constraint solver skipped where derods solves
        every row (see the module docstring)."""
        m = self.model
        self.skipped = False
        if not self.enabled and not self.exclusions:
            mujoco.mj_forward(m, d)
            return
        # mj_forward's own sequence, split after the rows are made: the position stage
        # here, the rest by mj_forwardSkip (flags reset as mj_forward resets them)
        d.flg_energypos = d.flg_energyvel = d.flg_rnepost = d.flg_subtreevel = 0
        mujoco.mj_fwdPosition(m, d)
        if self.exclusions:
            self.exclusions(d)
        if self.sensors:
            mujoco.mj_sensorPos(m, d)
        if self.energy:
            mujoco.mj_energyPos(m, d)
        nefc = d.nefc
        if not self.enabled or not nefc or not self._solve_all.keyed(
                (bool, int, int, d, d, d, d, d, self.supported, self.solved_dof),
                (self.is_sparse, nefc, m.nv, d.efc_J, d.efc_J_rownnz, d.efc_J_rowadr, d.efc_J_colind, d.efc_type,
                 self.supported, self.solved_dof)):
            mujoco.mj_forwardSkip(m, d, int(mujoco.mjtStage.mjSTAGE_POS), 0)
            return
        mujoco.mj_fwdVelocity(m, d)
        if self.sensors:
            mujoco.mj_sensorVel(m, d)
        if self.energy:
            mujoco.mj_energyVel(m, d)
        control = mujoco.get_mjcb_control()
        if control is not None:
            control(m, d)
        mujoco.mj_fwdActuation(m, d)
        mujoco.mj_fwdAcceleration(m, d)
        d.qacc[:] = d.qacc_smooth
        d.qfrc_constraint[:] = 0.0
        d.efc_force[:nefc] = 0.0
        self.skipped = True  # the acceleration-stage sensors come after derods' solve

    def sensors_after(self, d: mujoco.MjData) -> None:
        """The acceleration-stage sensors again, from the acceleration and row forces derods
        wrote (call after its solve)."""
        if self.acc_sensors:
            d.flg_rnepost = 0
            mujoco.mj_sensorAcc(self.model, d)
