"""Bodies that hold rod ends, coupled implicitly to the rods' step.

A vertex pinned or an edge clamped to a body with dofs (a free joint, slides, hinges,
chains of them) moves with that body, and the rod's force and twisting moment reach
the body. Applied one step late (:class:`derods.sim.clamps.Reactions` alone), the
rod's stiff stretching makes a light body diverge: the body's mass must exceed about
k_s h / 4 (measured: every body of 1e-3 to 1e3 times a 0.3 kg rod's mass diverged at
dt = 1e-2). Here the holders' dofs q enter the rods' implicit step instead (backward
Euler, linearized about the start of the step, s = h^2 + h b):

    A a_f + s K_fq a_q = r_f - (b + h) K_fq v_q                          (rod dofs)
    (M - h D) a_q + s (K_qf a_f + K_qq a_q) = f_q - (b + h) (K_qf v_f + K_qq v_q)

with E the rods' energy, K_fq = d grad_f E / dq and K_qq = d^2 E / dq^2 (so K_qf =
K_fq^T), f_q everything MuJoCo puts on the holders' dofs this step (the rods' reaction
at the start of the step, their own constraints from MuJoCo's solve, actuators,
damping), M MuJoCo's mass matrix and D its velocity derivative (``qDeriv``: joint
damping, actuators' kv, as MuJoCo's implicit integrators take it, or the joint damping
Euler's takes implicitly). Eliminating a_f with the rods' factored A (one banded solve
per holder dof) leaves a small dense system, the rods' stiffness as the holders feel
it being a Schur complement (A keeps its band):

    (M - h D + s K_qq - s^2 K_qf A^-1 K_fq) a_q = f_q - (b + h)(...) - s K_qf y0.

K's columns come from central differences over the holder dofs: each dof moved by
+-eps through ``mj_integratePos`` (rotations included), MuJoCo's kinematics on a
scratch copy of the data, the held vertices and clamp frames placed as the step
places them, the rods' gradient and generalized reaction evaluated. A clamp's edge
turns with its body, so the twisting moment and the turning edge are in these
columns too. The dofs solved are those of the kinematic trees the holders belong to
(M is block diagonal over trees, so MuJoCo's own implicit solve of those rows then
reproduces a_q exactly); trees with no rod attached stay MuJoCo's alone.
"""

from __future__ import annotations

import ctypes
import glob
import os

import mujoco
import numpy as np

from .._numba.coupling import gather_positions
from ..step import Frames, Terms, evaluate

#: The central-difference step for K's columns [relative to the shortest edge for a
#: translation, in rad for a rotation]: the gradient is smooth; round-off stays below
#: 1e-8 of K.
FD_STEP = 1e-6


def smooth_vel(model: mujoco.MjModel, data: mujoco.MjData, bias: bool) -> None:
    """MuJoCo's d (qfrc_actuator + qfrc_passive [- qfrc_bias]) / d qvel into data.qDeriv
    (sparse, MuJoCo's D layout), as its implicit integrators take it: MuJoCo's own
    mjd_smooth_vel, exported by libmujoco but not by the Python bindings."""
    global _MJD_SMOOTH_VEL
    if _MJD_SMOOTH_VEL is None:
        libs = glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco*"))
        if not libs:
            raise RuntimeError("the MuJoCo library was not found next to the mujoco package: the coupled "
                               "solve of bodies that MuJoCo damps implicitly needs its mjd_smooth_vel")
        fn = ctypes.CDLL(libs[0]).mjd_smooth_vel
        fn.argtypes, fn.restype = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int], None
        _MJD_SMOOTH_VEL = fn
    _MJD_SMOOTH_VEL(model._address, data._address, int(bias))


_MJD_SMOOTH_VEL = None


def chain_dofs(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The dofs that move ``body``: its own and its ancestors', shape (k,), int64."""
    dofs = []
    b = body
    while b > 0:
        dofs += range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b])
        b = model.body_parentid[b]
    return np.array(sorted(dofs), dtype=np.int64)


def tree_dofs(model: mujoco.MjModel, bodies) -> np.ndarray:
    """Every dof of the kinematic trees the given bodies belong to, sorted, int64."""
    dofs: set[int] = set()
    for b in bodies:
        t = int(model.body_treeid[b])
        if t >= 0:
            dofs.update(range(model.tree_dofadr[t], model.tree_dofadr[t] + model.tree_dofnum[t]))
    return np.array(sorted(dofs), dtype=np.int64)


def rotational(model: mujoco.MjModel, dof: int) -> bool:
    """Whether a dof turns its body (hinge, ball, a free joint's last three)."""
    j = int(model.dof_jntid[dof])
    kind = model.jnt_type[j]
    if kind == mujoco.mjtJoint.mjJNT_FREE:
        return dof - int(model.jnt_dofadr[j]) >= 3
    return kind in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_BALL)


class Holders:
    """The bodies with dofs that hold rod ends, and the coupled solve. Built once from
    the layout; ``bool(holders)`` is False (and costs nothing) when there are none.

    dofs (k,): the dofs that move a held vertex or clamp (the FD columns); tree (m,):
    every dof of their kinematic trees (the solved rows); both int64, sorted.
    """

    def __init__(self, model: mujoco.MjModel, layout, rods, band_rows: int, reactions):
        bodies = [int(b) for b in reactions.bodies if len(chain_dofs(model, int(b)))]
        self.bodies = np.array(bodies, dtype=np.int64)
        self.dofs = np.unique(np.concatenate([chain_dofs(model, b) for b in bodies])) if bodies \
            else np.zeros(0, dtype=np.int64)
        self.tree = tree_dofs(model, bodies)
        self._in_tree = np.searchsorted(self.tree, self.dofs)
        if not bodies:
            return
        self._scratch = mujoco.MjData(model)
        self._terms = Terms.empty(rods.n_rods, rods.n_vertices, layout.n, band_rows)
        self._xs = np.zeros_like(layout.x0)
        self._qfrc = np.zeros(model.nv)
        self._dq = np.zeros(model.nv)
        self._unit = np.zeros(model.nv)
        self._column = np.zeros(model.nv)
        edge = float(np.min(rods.rest_len))
        self._eps = np.array([FD_STEP if rotational(model, int(j)) else FD_STEP * edge for j in self.dofs])
        implicit = model.opt.integrator in (mujoco.mjtIntegrator.mjINT_IMPLICIT,
                                            mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
        #: Whether MuJoCo's integrator takes qDeriv (else Euler: joint damping only).
        self._implicit = implicit
        self._bias = int(model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICIT)

    def __bool__(self) -> bool:
        return len(self.dofs) > 0

    # -- the matrices -----------------------------------------------------------------
    def stiffness_columns(self, step) -> tuple[np.ndarray, np.ndarray]:
        """K's columns over the holder dofs at the step's state: k_f (n, k) = d grad_f / dq
        [N/m or N/rad] over the rods' free dofs, k_q (k, k) = d^2 E / dq^2, by central
        differences (each dof moved by +-eps on a scratch copy of MuJoCo's data)."""
        m, d, lay, fr = step.model, step.data, step.layout, step.frames
        ds, xs = self._scratch, self._xs
        k_f, k_q = np.zeros((lay.n, len(self.dofs))), np.zeros((len(self.dofs), len(self.dofs)))
        ds.mocap_pos[:], ds.mocap_quat[:] = d.mocap_pos, d.mocap_quat
        for j, dof in enumerate(self.dofs):
            eps = self._eps[j]
            grads, gens = [], []
            for sign in (1.0, -1.0):
                ds.qpos[:] = d.qpos
                self._dq[dof] = 1.0
                mujoco.mj_integratePos(m, ds.qpos, self._dq, sign * eps)
                self._dq[dof] = 0.0
                mujoco.mj_kinematics(m, ds)
                mujoco.mj_comPos(m, ds)
                gather_positions(lay.x0, ds.qpos, lay.qpos_adr, lay.free_vertex, ds.xpos, lay.moved_vertex,
                                 lay.moved_body, xs)
                frames = Frames(fr.u.copy(), fr.t.copy(), fr.theta.copy(), fr.theta_end.copy())
                evaluate(step.rods, frames, xs, lay.place, self._terms, step.ends, ds.xmat)
                grads.append(self._terms.grad[lay.free_vertex].ravel())
                q = step.reactions.generalized(m, ds, xs, self._terms.grad, frames.t, self._terms.end_moment,
                                               self._qfrc)
                gens.append(q[self.dofs].copy())
            k_f[:, j] = (grads[0] - grads[1]) / (2.0 * eps)
            k_q[:, j] = -(gens[0] - gens[1]) / (2.0 * eps)
        return k_f, k_q

    def mass_block(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """MuJoCo's mass matrix on the holders' trees, M[tree, tree] [kg or kg m^2], a
        column per dof through mj_mulM (a dense nv x nv matrix would not fit a large world)."""
        mass = np.empty((len(self.tree), len(self.tree)))
        for j, dof in enumerate(self.tree):
            self._unit[dof] = 1.0
            mujoco.mj_mulM(m, d, self._column, self._unit)
            self._unit[dof] = 0.0
            mass[:, j] = self._column[self.tree]
        return mass

    def damping_block(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """The velocity derivative MuJoCo's integrator solves with on the holders' trees,
        D[tree, tree] [N s/m or N m s]: qDeriv (mjd_smooth_vel) for the implicit ones, minus
        the joint damping for Euler's (unless disabled)."""
        k = len(self.tree)
        if not self._implicit:
            if m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP:
                return np.zeros((k, k))
            return -np.diag(m.dof_damping[self.tree])
        smooth_vel(m, d, self._bias)
        out = np.zeros((k, k))
        for i, dof in enumerate(self.tree):
            adr, nnz = int(m.D_rowadr[dof]), int(m.D_rownnz[dof])
            cols = m.D_colind[adr:adr + nnz]
            inside = np.searchsorted(self.tree, cols)
            ok = (inside < k) & (self.tree[np.minimum(inside, k - 1)] == cols)
            out[i, inside[ok]] = d.qDeriv[adr:adr + nnz][ok]
        return out

    # -- the step ---------------------------------------------------------------------
    def solve(self, step) -> None:
        """Couple the step's rods to their holders: replace step.a0 (the rods'
        unconstrained acceleration), and set the holders' trees' qacc and the force that
        makes MuJoCo's integrator reproduce it (call after MuJoCo's forward pass)."""
        m, d = step.model, step.data
        h, b = step.h, step.stiffness_damping
        s = h * h + h * b
        k_f, k_q = self.stiffness_columns(step)
        v_q = d.qvel[self.dofs]
        y = step.system.solve(s * k_f)  # A^-1 s K_fq, (n, k)
        y0 = step.a0 - (b + h) / s * (y @ v_q)
        mass, damp = self.mass_block(m, d), self.damping_block(m, d)
        lhs = mass - h * damp
        c = self._in_tree
        lhs[np.ix_(c, c)] += s * k_q - s * (k_f.T @ y)
        force = d.qfrc_smooth[self.tree] + d.qfrc_constraint[self.tree]
        force[c] -= (b + h) * (k_f.T @ step.v + k_q @ v_q) + s * (k_f.T @ y0)
        a_t = np.linalg.solve(lhs, force)
        step.a0[:] = y0 - y @ a_t[c]
        d.qacc[self.tree] = a_t
        # MuJoCo's integrator solves (M - h D) qacc = qfrc_smooth + qfrc_constraint; on the
        # holders' trees (M and D block diagonal over trees) this force gives a_t back.
        d.qfrc_constraint[self.tree] = (mass - h * damp) @ a_t - d.qfrc_smooth[self.tree]
