"""The correction of MuJoCo's contact rows before derods solves them
(:class:`ReferenceCorrection`): mocap bodies, which move without dofs, get the velocity of
their last move, so that a row against one sees the approach and not only the penetration
the move left; and a row within a rod's contact margin (speculative contacts,
``ContactParams.margin``) only keeps the end-of-step position from crossing the surface,
instead of MuJoCo's reading of a margin as a skin to push out of. The compiled correction
is :func:`derods._numba.contact_reference.correct_aref`; the solve that reads the rows,
:mod:`derods.sim.contact`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba.contact_reference import Contacts, Jacobian, correct_aref

#: The contact types the correction reads (MuJoCo's frictionless, pyramidal, elliptic).
_KINDS = np.array([int(mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS),
                   int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
                   int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC)])


class ReferenceCorrection:
    """Mocap bodies' velocities, from their poses in consecutive steps, and the
    correction of contact rows to them and to speculative margins (see the module
    docstring). ``margin``: whether any rod has a contact margin.

    Call :meth:`update` once per step after the mocap poses for the step are set and
    before MuJoCo's forward pass; :meth:`correct` after it, before the rows are solved.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, margin: bool):
        self.body = np.flatnonzero(model.body_mocapid >= 0)
        self.slot = model.body_mocapid[self.body]
        self.pos = data.mocap_pos.copy()
        self.quat = data.mocap_quat.copy()
        self.vel = np.zeros((model.nbody, 6))
        self.moving = np.zeros(model.nbody, dtype=bool)
        self.any_moving = False
        self.margin = margin
        self.h = float(model.opt.timestep)
        #: [m] How deep a slowly approached row with a margin lets a vertex end its step
        #: (correct_aref): the speed margins' sink depth where rods have them
        #: (derods.sim.speculative), else 0, so that rows of static margins (hair's, the
        #: pile's) keep rods out altogether, as they always did.
        self.sink = 0.0
        self.geom_body = np.ascontiguousarray(model.geom_bodyid, dtype=np.int64)
        self.is_sparse = bool(mujoco.mj_isSparse(model))
        self.model_nv = int(model.nv)
        self._dq = np.zeros(4)
        self._w = np.zeros(3)

    def __bool__(self) -> bool:
        return len(self.body) > 0 or self.margin

    def update(self, data: mujoco.MjData) -> None:
        """Velocities [m/s, rad/s] of the mocap bodies over the last step."""
        self.any_moving = False
        for b, k in zip(self.body, self.slot):
            lin = (data.mocap_pos[k] - self.pos[k]) / self.h
            # world-frame rotation from the old orientation to the new
            mujoco.mju_mulQuat(self._dq, data.mocap_quat[k], self.quat[k] * np.array([1.0, -1.0, -1.0, -1.0]))
            mujoco.mju_quat2Vel(self._w, self._dq, self.h)
            self.vel[b, :3], self.vel[b, 3:] = lin, self._w
            self.moving[b] = bool(np.any(lin != 0.0) or np.any(self._w != 0.0))
            self.any_moving |= self.moving[b]
        self.pos[:] = data.mocap_pos
        self.quat[:] = data.mocap_quat

    def correct(self, data: mujoco.MjData) -> None:
        """Correct the contact rows' reference accelerations in ``data.efc_aref``."""
        if not (self.any_moving or self.margin) or data.ncon == 0:
            return
        con = data.contact
        contacts = Contacts(data.ncon, con.geom, con.pos, con.frame, con.dim, con.friction, con.efc_address)
        jac = Jacobian(data.efc_J, data.efc_J_rownnz, data.efc_J_rowadr, self.is_sparse, self.model_nv)
        correct_aref(contacts, self.geom_body, self.moving, self.vel, data.xpos, data.efc_type, data.efc_pos,
                     data.efc_margin, data.efc_vel, data.efc_KBIP, data.efc_aref, self.h, _KINDS, jac, self.sink)
