"""MuJoCo's side of a coupled solve: kinematic trees, their inertia as MuJoCo's
integrator takes it, and writing back an acceleration it reproduces.

When derods solves the motion of some MuJoCo bodies together with its rods (bodies
holding rod ends, :mod:`derods.sim.holders`; bodies touching rods, :mod:`derods.sim.contact`),
it works on whole kinematic trees: MuJoCo's mass matrix M is block diagonal over trees,
and so is the velocity derivative D its integrators treat implicitly (joint damping,
actuators' kv; tendons or actuators spanning two trees aside). On a tree's dofs
MuJoCo's integrator solves (M - h D) qacc = qfrc_smooth + qfrc_constraint; derods
writes the force that makes that solve return the acceleration it found
(:class:`TreeDynamics`).
"""

from __future__ import annotations

import ctypes
import glob
import os

import mujoco
import numpy as np

from .._numba.dense import damped_block_into, sparse_block_into

_MJD_SMOOTH_VEL = None
#: The disable bit of Euler's implicit joint damping, as an int: a pybind enum costs ~0.2 us
#: an operation, and :meth:`TreeDynamics.metric` runs every step.
_EULERDAMP = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)


def smooth_vel(model: mujoco.MjModel, data: mujoco.MjData, bias: bool) -> None:
    """MuJoCo's d (qfrc_actuator + qfrc_passive [- qfrc_bias]) / d qvel into data.qDeriv
    (sparse, MuJoCo's D layout), as its implicit integrators take it: MuJoCo's own
    mjd_smooth_vel, exported by libmujoco but not by the Python bindings."""
    global _MJD_SMOOTH_VEL
    if _MJD_SMOOTH_VEL is None:
        libs = glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco*"))
        if not libs:
            raise RuntimeError("the MuJoCo library was not found next to the mujoco package: coupling rods to "
                               "bodies that MuJoCo damps implicitly needs its mjd_smooth_vel")
        fn = ctypes.CDLL(libs[0]).mjd_smooth_vel
        fn.argtypes, fn.restype = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int], None
        _MJD_SMOOTH_VEL = fn
    _MJD_SMOOTH_VEL(model._address, data._address, int(bias))


def trees_of(model: mujoco.MjModel, bodies) -> np.ndarray:
    """The kinematic trees (ids, sorted, int64) the given bodies belong to (the world and
    static bodies belong to none)."""
    trees = model.body_treeid[np.asarray(bodies, dtype=np.int64)]
    return np.unique(trees[trees >= 0]).astype(np.int64)


def tree_dofs(model: mujoco.MjModel, trees: np.ndarray) -> np.ndarray:
    """Every dof of the given trees (sorted ids), int64: sorted too, as MuJoCo numbers trees
    and dofs in body order."""
    if len(trees) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([np.arange(model.tree_dofadr[t], model.tree_dofadr[t] + model.tree_dofnum[t])
                           for t in trees]).astype(np.int64)


class TreeDynamics:
    """M and D of one model on a set of tree dofs (sorted, int64), and the write-back;
    one instance serves any set of its dofs."""

    def __init__(self, model: mujoco.MjModel):
        self.implicit = model.opt.integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT,
                                                 mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
        self._bias = int(model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICIT)
        #: data.M's sparsity (fixed by the model)
        self._m_rows = (model.M_rowadr.astype(np.int64), model.M_rownnz.astype(np.int64),
                        model.M_colind.astype(np.int64))
        self._no_damping = np.zeros(model.nv)

    def mass(self, m: mujoco.MjModel, d: mujoco.MjData, dofs: np.ndarray) -> np.ndarray:
        """MuJoCo's mass matrix M[dofs, dofs] [kg or kg m^2] for sorted ``dofs``, read from its
        sparse ``data.M`` (a dense nv x nv matrix would not fit a large world)."""
        out = np.empty((len(dofs), len(dofs)))
        sparse_block_into(d.M, *self._m_rows, np.ascontiguousarray(dofs, dtype=np.int64), out)
        return out

    def damping(self, m: mujoco.MjModel, d: mujoco.MjData, dofs: np.ndarray) -> np.ndarray:
        """The velocity derivative D[dofs, dofs] [N s/m or N m s] MuJoCo's integrator solves
        with: qDeriv (mjd_smooth_vel) for the implicit ones, minus the joint damping for
        Euler's (unless disabled)."""
        k = len(dofs)
        if not self.implicit:
            return np.diag(self._euler_damping(m, dofs))
        smooth_vel(m, d, self._bias)
        out = np.zeros((k, k))
        for i, dof in enumerate(dofs):
            adr, nnz = int(m.D_rowadr[dof]), int(m.D_rownnz[dof])
            cols = m.D_colind[adr:adr + nnz]
            inside = np.searchsorted(dofs, cols)
            ok = (inside < k) & (dofs[np.minimum(inside, k - 1)] == cols)
            out[i, inside[ok]] = d.qDeriv[adr:adr + nnz][ok]
        return out

    def metric(self, m: mujoco.MjModel, d: mujoco.MjData, dofs: np.ndarray) -> np.ndarray:
        """M - h D on dofs: the matrix MuJoCo's integrator solves with."""
        if not self.implicit:  # Euler's D is diagonal: onto M's diagonal, in one compiled call
            out = np.empty((len(dofs), len(dofs)))
            opt = m.opt
            eulerdamp = not opt.disableflags & _EULERDAMP
            damped_block_into(d.M, *self._m_rows, np.ascontiguousarray(dofs, dtype=np.int64),
                              m.dof_damping if eulerdamp else self._no_damping, opt.timestep, out)
            return out
        return self.mass(m, d, dofs) - m.opt.timestep * self.damping(m, d, dofs)

    @staticmethod
    def _euler_damping(m: mujoco.MjModel, dofs: np.ndarray) -> np.ndarray:
        """The diagonal of D (k,) [N s/m or N m s] MuJoCo's Euler integrator solves with: minus
        the joint damping, which it takes implicitly (zero when that is disabled)."""
        if m.opt.disableflags & _EULERDAMP:
            return np.zeros(len(dofs))
        return -m.dof_damping[dofs]

    @staticmethod
    def write(d: mujoco.MjData, dofs: np.ndarray, metric: np.ndarray, qacc: np.ndarray) -> None:
        """Set qacc on whole trees' dofs and the constraint force that makes MuJoCo's
        integrator, solving (M - h D) qacc = qfrc_smooth + qfrc_constraint, return it."""
        d.qacc[dofs] = qacc
        d.qfrc_constraint[dofs] = metric @ qacc - d.qfrc_smooth[dofs]
