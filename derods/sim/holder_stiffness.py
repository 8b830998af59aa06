"""The rods' stiffness as the holders of rod ends feel it: K's columns over the holder dofs
(:class:`HolderStiffness`, the part of :class:`derods.sim.holders.Holders` that computes
them each step) and the helpers they are made with.

K_fq = K_fh J + F: K_fh the Gauss-Newton blocks between free and held vertices, from the
compiled step itself (every vertex given a place in its rod's band), J the held points'
Jacobian (mj_jac), F what turning a clamp's frame does to the free vertices' force; F and
the rotations' K_qq come from central differences over the holder dofs, the translations'
K_qq from the band's own blocks (see :mod:`derods.sim.holders` for the coupled step these
enter and what was measured).
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from .._numba.coupling import gather_into, gather_positions
from ..step import evaluate


class Stiffness(NamedTuple):
    """The rods' stiffness as the holders' dofs (k of them) and held points (H) see it."""

    k_f: np.ndarray   #: (n, k) [N/m or N/rad]: d grad_f / dq over the rods' free dofs
    k_q: np.ndarray   #: (k, k): d^2 E / dq^2
    k_fh: np.ndarray  #: (n, 3H) [N/m]: Gauss-Newton blocks between free dofs and held points
    k_hh: np.ndarray  #: (3H, 3H) [N/m]: the same among the held points
    jac: np.ndarray   #: (3H, k): the held points' motion per holder dof (mj_jac)


#: The central-difference step for K's columns [relative to the shortest edge for a
#: translation, in rad for a rotation]: the gradient is smooth; round-off stays below
#: 1e-8 of K.
FD_STEP = 1e-6


def rotational(model: mujoco.MjModel, dof: int) -> bool:
    """Whether a dof turns its body (hinge, ball, a free joint's last three)."""
    j = int(model.dof_jntid[dof])
    kind = int(model.jnt_type[j])  # an int: `numpy.int32 in (mjtJoint, ...)` is always False
    if kind == int(mujoco.mjtJoint.mjJNT_FREE):
        return dof - int(model.jnt_dofadr[j]) >= 3
    return kind in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_BALL))


def translation_mode(model: mujoco.MjModel, layout, dofs: np.ndarray, bodies) -> np.ndarray | None:
    """The motion of the holder dofs ``dofs`` (k, 3) that translates every held rod vertex
    rigidly along x, y, z, when the rods and their holders can translate freely together:
    every held vertex on one of ``bodies``' trees, each rooted in a free joint (whose
    first three dofs are world-frame translations). None otherwise (a vertex held by the
    world or a mocap body, a tree rooted in other joints: the momentum is not theirs)."""
    roots = {int(model.body_rootid[b]) for b in bodies}
    if len(layout.moved_vertex) != int(np.sum(layout.place < 0)):
        return None
    if not all(int(model.body_rootid[b]) in roots for b in layout.moved_body):
        return None
    mode = np.zeros((len(dofs), 3))
    for root in roots:
        j = int(model.body_jntadr[root])
        if model.body_jntnum[root] < 1 or model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            return None
        for a in range(3):
            mode[np.searchsorted(dofs, int(model.jnt_dofadr[j]) + a), a] = 1.0
    return mode


def gather(bands: np.ndarray, entries: tuple[np.ndarray, ...], shape: tuple[int, int]) -> np.ndarray:
    """The dense matrix of ``shape`` with the bands' (n_bands, rows, n) entries placed by
    :func:`band_entries`' index arrays."""
    out = np.empty(shape)
    gather_into(bands, *entries, out)
    return out


def invariant(k_qq: np.ndarray, k_qf_sum: np.ndarray, mode: np.ndarray) -> np.ndarray:
    """k_qq (k, k) made symmetric and exact on the translation mode (k, 3): the nearest
    symmetric matrix K with K mode = -k_qf_sum (k, 3) (= -K_qf 1, what translation
    invariance of the energy asks), by a symmetric rank-six correction."""
    k = 0.5 * (k_qq + k_qq.T)
    p = mode @ np.linalg.inv(mode.T @ mode)
    r = k @ mode + k_qf_sum
    return k - r @ p.T - p @ r.T + p @ (mode.T @ r) @ p.T


def gauss_newton(jac: np.ndarray, k_hh: np.ndarray) -> np.ndarray:
    """J^T K_hh J made symmetric: the Gauss-Newton K_qq [N/m or N m/rad] (k, k) of holder
    dofs whose held points move by jac (3H, k), k_hh (3H, 3H) the band's blocks among them."""
    gn = jac.T @ k_hh @ jac
    return 0.5 * (gn + gn.T)


def no_softer(k: np.ndarray, gn: np.ndarray) -> np.ndarray:
    """A block of K_qq (r, r) [N/m, N/rad or N m/rad] made no softer than its Gauss-Newton
    part gn (:func:`gauss_newton`): gn plus only the positive part (by eigenvalues) of what
    the differences add to it (the rods' geometric stiffness at the held points, the
    levers, a clamp's own bending and twisting).

    The band and K_fq are Gauss-Newton, PSD; the differenced block is exact and may be
    indefinite. Mixed, the holders' Schur complement can drift below their inertia: a 50 g
    arm on a hinge under a moving mocap base, clamping a 0.5 m rod, went from 0.0100 to
    below the arm's 0.00052 kg m^2 over ten steps while swinging back, and diverged (dt
    1e-2, the base moving 1 cm). Kept at least Gauss-Newton, the Schur complement stays
    above the inertia (a Schur complement of a PSD matrix adds to it); the negative part
    left out acts one step late, as in the rods' own band. Where clamps turn their frames,
    the cross terms between a body's translations and rotations carry the clamp's bending
    too, and the whole K_qq is kept so; where only points are held, the cross terms are the
    levers alone, and the whole kept so made a 1 g box landing on its pinned rod at dt 5e-3
    diverge: there only the rotations' block is. (The whole-K_qq rule for clamps was
    brought in against a clamping body whose pitch grew 3-5x a step; that was the stale
    com positions of :meth:`derods.sim.integrators.Step.elastic`, since fixed. Measured
    after the fix, the held sweep: 35 of 44 span cases right with the whole-K_qq rule, 34
    with the rotations' block alone, every other case the same.)"""
    lam, vec = np.linalg.eigh(0.5 * (k + k.T) - gn)
    return gn + (vec * np.maximum(lam, 0.0)) @ vec.T


class HolderStiffness:
    """K's columns over the holder dofs, for :class:`derods.sim.holders.Holders` (which
    holds the dofs, held points, scratch data and bands these read)."""

    # -- the matrices -----------------------------------------------------------------
    def stiffness_columns(self, step) -> Stiffness:
        """K's columns over the holder dofs at the step's state (a :class:`Stiffness`):
        k_f (n, k) = d grad_f / dq [N/m or N/rad] over the rods' free dofs, k_q (k, k) =
        d^2 E / dq^2, and the pieces k_f is made of.

        k_f = K_fh J + F: K_fh the Gauss-Newton blocks between free and held vertices (the
        compiled step's, the same the band holds, so that a rigid translation of rod and
        holders costs no force: K_ff 1 + K_fh 1 = 0), J the held points' motion per dof
        and F what turning a clamp's frame does to the free vertices' force; J from
        mj_jac (exact: K is stiff, a difference's round-off in J leaked momentum), F and k_q
        by central differences (each dof moved by +-eps on a scratch copy of MuJoCo's
        data). Where rods and holders float freely (:func:`translation_mode`), k_q is made
        exact on the translations too (:func:`invariant`): linear momentum is kept.
        """
        if not self.turning:
            return self._slide_stiffness(step)
        m, d, lay, fr = step.model, step.data, step.layout, step.frames
        ds, xs, x = self._scratch, self._xs, step.x
        k = len(self.dofs)
        frame, k_q = np.zeros((lay.n, k)), np.zeros((k, k))
        ds.mocap_pos[:], ds.mocap_quat[:] = d.mocap_pos, d.mocap_quat
        if self._turns is None:  # clamps on bodies turn their frames (the world's layout: fixed)
            self._turns = bool(np.any(step.ends.body >= 0))
        turns = self._turns
        for j, dof in enumerate(self.dofs):
            if not self._eps_rot[j]:
                continue  # a translation: its row and column are the band's (below)
            eps = self._eps[j]
            gens, grads = [], []
            for sign in (1.0, -1.0):
                ds.qpos[:] = d.qpos
                self._dq[dof] = 1.0
                mujoco.mj_integratePos(m, ds.qpos, self._dq, sign * eps)
                self._dq[dof] = 0.0
                mujoco.mj_kinematics(m, ds)
                mujoco.mj_comPos(m, ds)
                gather_positions(lay.x0, ds.qpos, lay.qpos_adr, lay.free_vertex, ds.xpos, lay.moved_vertex,
                                 lay.moved_body, xs)
                frames = fr.copy()
                evaluate(step.rods, frames, xs, lay.place, self._terms, step.ends, ds.xmat)
                q = step.reactions.generalized(m, ds, xs, self._terms.grad, frames.t, self._terms.end_moment,
                                               self._qfrc)
                gens.append(q[self.dofs].copy())
                if turns and self._eps_rot[j]:
                    # the clamp frames turned, the vertices kept: F's column
                    evaluate(step.rods, fr.copy(), x, lay.place, self._terms, step.ends, ds.xmat)
                    grads.append(self._terms.grad[lay.free_vertex].ravel())
            k_q[:, j] = -(gens[0] - gens[1]) / (2.0 * eps)
            if grads:
                frame[:, j] = (grads[0] - grads[1]) / (2.0 * eps)
        jac = self._held_jacobian(m, d, x)  # exact
        k_fh = self.held_blocks(step)
        k_f = k_fh @ jac + frame
        # Translations: K_qq's rows and columns J^T K_hh J, the band's own Gauss-Newton blocks
        # (moving a body along a line moves its held points rigidly, no lever turns); the
        # rotations' by the differences above; all of it kept no softer than Gauss-Newton
        # (no_softer): the rotations' block alone where only points are held, the whole of
        # K_qq where clamps turn their frames.
        t, r = ~self._eps_rot, self._eps_rot
        k_hh = gather(self._bands, self._held_blocks, (3 * len(self.held), 3 * len(self.held)))
        gn = gauss_newton(jac, k_hh)
        if t.any():
            k_q[np.ix_(t, t)] = gn[np.ix_(t, t)]
            k_q[np.ix_(r, t)] = k_q[np.ix_(t, r)].T  # the rotations' columns, differenced, give both
        if turns:
            k_q = no_softer(k_q, gn)
        else:
            rr = np.ix_(r, r)
            k_q[rr] = no_softer(k_q[rr], gn[rr])
        if self._translation is not None:
            # K_qf times every free vertex moved along x, y, z: k_f's rows summed by axis
            k_q = invariant(k_q, k_f.reshape(-1, 3, k).sum(axis=0).T, self._translation)
        return Stiffness(k_f, k_q, k_fh, k_hh, jac)

    def _slide_stiffness(self, step) -> Stiffness:
        """:meth:`stiffness_columns` where every holder dof is a slide (carts, gantries): the
        held points move along the slides' axes, fixed in the world, so J is constant
        (taken once) and there is nothing to difference: K_qq = J^T K_hh J."""
        if self._slide_jac is None:
            self._slide_jac = self._held_jacobian(step.model, step.data, step.x)
        jac = self._slide_jac
        k_fh = self.held_blocks(step)
        k_hh = gather(self._bands, self._held_blocks, (3 * len(self.held), 3 * len(self.held)))
        return Stiffness(k_fh @ jac, gauss_newton(jac, k_hh), k_fh, k_hh, jac)

    def _held_jacobian(self, m: mujoco.MjModel, d: mujoco.MjData, x: np.ndarray) -> np.ndarray:
        """The held points' motion per holder dof (3H, k), by mj_jac at positions x
        (n_vertices, 3) [m] in data d's kinematics."""
        jac = np.empty((3 * len(self.held), len(self.dofs)))
        for c, (v, b) in enumerate(zip(self.held, self.held_body)):
            mujoco.mj_jac(m, d, self._jacp, self._jacr, x[v], int(b))
            jac[3 * c:3 * c + 3] = self._jacp[:, self.dofs]
        return jac

    def held_blocks(self, step) -> np.ndarray:
        """K_fh (n, 3H) [N/m]: the Gauss-Newton Hessian blocks between the rods' free dofs and
        the held vertices (with each held-both-ends rod's rank-one twist term), from one
        compiled evaluation in which every vertex has a place in its rod's band."""
        lay = step.layout
        if self._fresh:  # the step's own evaluation filled the bands (see evaluate)
            t = step.terms
            self._fresh = False
        else:
            t = self._terms_all
            evaluate(step.rods, step.frames.copy(), step.x, self._place_all, t, step.ends, step.xmat, np.inf,
                     self._bands, self._band_of_rod)
        out = gather(self._bands, self._blocks, (lay.n, 3 * len(self.held)))
        if self._twisted is None:  # which held vertices' rods are held at both ends (fixed at compile)
            self._twisted = np.flatnonzero(np.isin(self.rod_of_held, step.rod_tw))
        v_off = step.rods.v_off
        for c in self._twisted:
            h, rod = self.held[c], self.rod_of_held[c]
            lo, hi = v_off[rod], v_off[rod + 1]
            free = lay.place[lo:hi] >= 0
            g_f = np.zeros(lay.n)
            g_f.reshape(-1, 3)[lay.place[lo:hi][free]] = t.g_tw[lo:hi][free]
            out[:, 3 * c:3 * c + 3] += step.terms.coef[rod] * np.outer(g_f, t.g_tw[h])
        return out
