"""Bodies that hold rod ends, coupled implicitly to the rods' step.

A vertex held by a body with dofs (a free joint, slides, hinges, chains of them) moves
with that body, and the rod's force on it reaches the body. Applied one step late
(:class:`derods.sim.clamps.Reactions` alone), the rod's stiff stretching makes a light
body diverge: the body's mass must exceed about k_s h / 4 (measured: every body of
1e-3 to 1e3 times a 0.3 kg rod's mass diverged at dt = 1e-2). Here the held vertices'
motion enters the implicit step instead (backward Euler, linearized):

    A a_f + s K_fh a_h = r_f - (b + h) K_fh v_h                   (the rod's free dofs)
    M_b a_b = tau_b + J^T f_h,   a_h = J a_b                       (the holders' dofs)
    f_h = -grad_h - (b + h) (K_hf v_f + K_hh v_h) - s (K_hf a_f + K_hh a_h)

with s = h^2 + h b, J the held points' Jacobian (MuJoCo's mj_jac), tau_b everything
MuJoCo puts on the holders' dofs but the rods (their own constraints included, from
MuJoCo's solve of this step). Eliminating a_f with the rods' factored A (three solves
per held vertex) leaves a small dense system for the holders' dofs,

    (M_b + J^T S J) a_b = tau_b + J^T F,   S = s K_hh - s^2 K_hf A^-1 K_fh,

the rods' stiffness as the holders feel it (a Schur complement: A keeps its band). The
columns of K at the held vertices come from central differences of the compiled
gradient (the band holds only free dofs). Pinned ends only, for now: a clamped end's
edge turns with its holder's orientation as well, which these columns (vertices moved,
the holder's frame kept) miss; clamped ends keep the explicit reaction of
:class:`~derods.sim.clamps.Reactions`, and so do holders whose chain MuJoCo damps
implicitly (joint damping, actuators on its joints: :func:`damped`), whose implicit
damping term this solve does not carry.
"""

from __future__ import annotations

import mujoco
import numpy as np

from ..step import Frames, Terms, evaluate

#: The central-difference step for K's columns at held vertices [relative to the
#: shortest edge]: the gradient is smooth; round-off stays below 1e-8 of K.
FD_STEP = 1e-6


def chain_dofs(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The dofs that move ``body``: its own and its ancestors', shape (k,), int64."""
    dofs = []
    b = body
    while b > 0:
        dofs += range(model.body_dofadr[b], model.body_dofadr[b] + model.body_dofnum[b])
        b = model.body_parentid[b]
    return np.array(sorted(dofs), dtype=np.int64)


def damped(model: mujoco.MjModel, body: int) -> bool:
    """Whether MuJoCo integrates a velocity dependence of ``body``'s chain implicitly (joint
    damping, or an actuator on one of its joints): the solve here does not carry MuJoCo's
    implicit damping term, so such holders keep the explicit reaction."""
    dofs = chain_dofs(model, body)
    if np.any(model.dof_damping[dofs] > 0):
        return True
    joints = set(int(model.dof_jntid[k]) for k in dofs)
    return any(model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and int(model.actuator_trnid[a, 0]) in joints
               for a in range(model.nu))


class Holders:
    """The held vertices whose holders have dofs, and the coupled solve. Built once from
    the layout; ``bool(holders)`` is False (and costs nothing) when there are none."""

    def __init__(self, model: mujoco.MjModel, layout, rods, band_rows: int, entries=()):
        # Pinned ends only: a clamp's edge turns with its body's orientation too, which the
        # vertex-wise stiffness columns here do not see (coupling it so made a light
        # motor's clamp diverge); clamped ends keep the explicit reaction.
        clamped = set()
        for i, e in enumerate(entries):
            for key in ("start", "end"):
                if (e.start if key == "start" else e.end) == "clamp" and e.holder(key) is not None:
                    clamped.update(int(layout.v_off[i] + v) for v in e.held(key))
        self.vertex, self.body = [], []
        for v, b in zip(layout.moved_vertex, layout.moved_body):
            if int(v) not in clamped and len(chain_dofs(model, int(b))) and not damped(model, int(b)):
                self.vertex.append(int(v))
                self.body.append(int(b))
        self.vertex = np.array(self.vertex, dtype=np.int64)
        self.body = np.array(self.body, dtype=np.int64)
        self.dofs = np.unique(np.concatenate([chain_dofs(model, b) for b in self.body])) if len(self.body) \
            else np.zeros(0, dtype=np.int64)
        self._terms = Terms.empty(rods.n_rods, rods.n_vertices, layout.n, band_rows)
        self._unit = np.zeros(model.nv)
        self._column = np.zeros(model.nv)
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))

    def __bool__(self) -> bool:
        return len(self.vertex) > 0

    def stiffness_columns(self, step, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """K's columns at the held vertices: (k_f (n, 3H) over the free dofs, k_h (3H, 3H)
        between held vertices) [N/m], by central differences of the gradient at x."""
        lay, fr = step.layout, step.frames
        eps = FD_STEP * float(np.min(step.rods.rest_len))
        nh = len(self.vertex)
        k_f, k_h = np.zeros((lay.n, 3 * nh)), np.zeros((3 * nh, 3 * nh))
        xp = x.copy()
        for i, v in enumerate(self.vertex):
            for a in range(3):
                grads = []
                for sign in (1.0, -1.0):
                    xp[v, a] = x[v, a] + sign * eps
                    copy = Frames(fr.u.copy(), fr.t.copy(), fr.theta.copy(), fr.theta_end.copy())
                    evaluate(step.rods, copy, xp, lay.place, self._terms, step.ends, step.xmat)
                    grads.append(self._terms.grad.copy())
                xp[v, a] = x[v, a]
                col = (grads[0] - grads[1]) / (2.0 * eps)
                k_f[:, 3 * i + a] = col[lay.free_vertex].ravel()
                k_h[:, 3 * i + a] = col[self.vertex].ravel()
        return k_f, k_h

    def mass_block(self, m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
        """MuJoCo's mass matrix on the holders' dofs, M[dofs, dofs] (k, k) [kg or kg m^2], a
        column per dof through mj_mulM (a dense nv x nv matrix would not fit a large world)."""
        mass = np.empty((len(self.dofs), len(self.dofs)))
        for j, dof in enumerate(self.dofs):
            self._unit[dof] = 1.0
            mujoco.mj_mulM(m, d, self._column, self._unit)
            self._unit[dof] = 0.0
            mass[:, j] = self._column[self.dofs]
        return mass

    def solve(self, step) -> None:
        """Couple the step's rods to their holders: replace step.a0 (the rods'
        unconstrained acceleration) and write the holders' qacc (call after MuJoCo's
        forward pass of the step)."""
        m, d = step.model, step.data
        h, b = step.h, step.stiffness_damping
        s = h * h + h * b
        x = step.x
        k_f, k_h = self.stiffness_columns(step, x)
        dofs = self.dofs
        jac = np.zeros((3 * len(self.vertex), len(dofs)))
        for i, (v, body) in enumerate(zip(self.vertex, self.body)):
            mujoco.mj_jac(m, d, self._jacp, self._jacr, x[v], int(body))
            jac[3 * i:3 * i + 3] = self._jacp[:, dofs]
        v_h = jac @ d.qvel[dofs]
        y = step.system.solve(s * k_f)  # A^-1 s K_fh, (n, 3H)
        y0 = step.a0 - step.system.solve((b + h) * (k_f @ v_h))
        grad_h = step.terms.grad[self.vertex].ravel()
        force = -grad_h - (b + h) * (k_f.T @ step.v + k_h @ v_h) - s * (k_f.T @ y0)
        schur = s * k_h - s * (k_f.T @ y)
        mass = self.mass_block(m, d)
        # What MuJoCo puts on the holders' dofs, without the rods' explicit reaction.
        tau = d.qfrc_smooth[dofs] - step.reactions.pin_applied(m, d, self.vertex)[dofs] + d.qfrc_constraint[dofs]
        a_b = np.linalg.solve(mass + jac.T @ schur @ jac, tau + jac.T @ force)
        step.a0[:] = y0 - y @ (jac @ a_b)
        d.qacc[dofs] = a_b
        d.qfrc_constraint[dofs] = mass @ a_b - d.qfrc_smooth[dofs]
