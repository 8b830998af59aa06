"""Reference accelerations of MuJoCo's contact rows corrected for what derods solves,
compiled: the motion of bodies moved without dofs (mocap bodies), and speculative rows
(a contact margin). The stage around it is :class:`derods.sim.contact_reference.ReferenceCorrection`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np


class Contacts(NamedTuple):
    """MuJoCo's contacts (data.contact): count (ncon); per contact its geoms geom (ncon, 2),
    point pos (ncon, 3) [m], frame (ncon, 9), dim, friction (ncon, 5) and first row
    efc_address."""

    count: int
    geom: np.ndarray
    pos: np.ndarray
    frame: np.ndarray
    dim: np.ndarray
    friction: np.ndarray
    efc_address: np.ndarray


class Jacobian(NamedTuple):
    """MuJoCo's constraint Jacobian efc_J, sparse (CSR: rownnz, rowadr and the values) or
    dense (nefc x nv, row-major); rownnz, rowadr are empty for a dense one."""

    values: np.ndarray
    rownnz: np.ndarray
    rowadr: np.ndarray
    sparse: bool
    nv: int


#: A speculative contact approached by at most this many times its sink depth in a step
#: settles in by the sink (resting, sliding, a hop's landing); a faster one is stopped at the
#: surface (:func:`correct_aref`). Let a fast one sink too, a cable landing at 1.8 m/s on a
#: heap arrived inside the cables below with its speed, their rows no longer speculative,
#: and pushed them 7 mm into the floor (16 cables, dt 1/120 s, margin r); 1 sink: a hopping
#: cable's landings were stopped a hair above the floor, without friction for a step (a
#: dragged cable felt 0.970 of Coulomb's friction, 0.992 at 3).
SETTLING = 3.0


@nb.njit(cache=True)
def _normal_rows(jac, efc_vel, adr, n_rows, vel):
    """A pyramidal contact's rows n + mu_k c_k, n - mu_k c_k (from adr, n_rows of them)
    all made its normal n, each pair's mean, in jac's values; vel (n_rows,): their
    velocities J qdot made the normal's too."""
    for k in range(n_rows // 2):
        r0, r1 = adr + 2 * k, adr + 2 * k + 1
        if jac.sparse:  # the rows of one contact share their columns (MuJoCo's chain)
            a0, a1, count = jac.rowadr[r0], jac.rowadr[r1], jac.rownnz[r0]
        else:
            a0, a1, count = r0 * jac.nv, r1 * jac.nv, jac.nv
        for i in range(count):
            mean = 0.5 * (jac.values[a0 + i] + jac.values[a1 + i])
            jac.values[a0 + i] = mean
            jac.values[a1 + i] = mean
        mean = 0.5 * (efc_vel[r0] + efc_vel[r1])
        vel[2 * k] = mean
        vel[2 * k + 1] = mean


@nb.njit(cache=True)
def correct_aref(contacts, geom_body, moving, body_vel, xpos, efc_type, efc_pos, efc_margin, efc_vel, efc_kbip,
                 efc_aref, h, kinds, jac, sink):
    """Correct MuJoCo's contact rows' reference accelerations for what derods solves.

    1. Bodies that move without dofs (mocap bodies): MuJoCo's row i has
       aref_i = -B_i (J_i qdot) - K_i I_i r_i and cannot see their motion; a body with
       velocity (v, w) adds w_i = j_i . (relative velocity, geom[1]'s side minus geom[0]'s,
       at the contact point) to the row's velocity. moving (nbody,) bool; body_vel
       (nbody, 6): linear [m/s] and angular [rad/s] velocity, world frame; xpos (nbody, 3).
    2. Speculative rows (a margin > 0, see :class:`derods.sim.contact_params.ContactParams`):
       a row not yet touching (distance d >= 0) only keeps the end-of-step position
       from crossing the surface, d + h (v_i + h a_i) >= 0, so aref_i = -(d / h + v_i) / h;
       if its contact is approached slowly (by at most :data:`SETTLING` ``sink`` [m] in the
       step), deeper than ``sink`` (with speed-sized margins a resting vertex's fall in a step,
       :func:`derods.sim.speculative.sink_depth`; else 0), aref_i = -((d + sink) / h + v_i) / h: a rod
       resting or sliding on a surface ends the step touching it, with friction from the
       next (held a hair above it, a dragged cable felt 0.76 of Coulomb's friction);
       a moving body is already posed for the end of the step when MuJoCo measures d, so
       its velocity enters v_i only where it approaches (keeping clear of its next pose),
       never to allow the rod closer than its surface now;
       a touching one is MuJoCo's soft row without the margin, -B_i v_i - K_i I_i d.
       A speculative pyramidal contact carries no friction, as an elliptic one (whose
       cone is its normal row alone then, :mod:`derods._numba.cones`): its rows
       n +- mu c, each kept from crossing, would brake a rod sliding a hair above a
       surface (v_n h + d >= mu |v_t| h); they are made its normal row n, in MuJoCo's
       Jacobian ``jac`` (:class:`Jacobian`) itself, which the solve reads next.
    Pyramidal, frictionless and elliptic rows (an elliptic contact's frictional rows have
    no margin of their own: they take the motion, its normal row the margin). contacts:
    MuJoCo's (:class:`Contacts`); efc_*: its rows' arrays; h: step [s]; kinds (3,):
    MuJoCo's frictionless, pyramidal and elliptic contact types.
    """
    frictionless, pyramidal, elliptic = kinds[0], kinds[1], kinds[2]
    ncon, con_geom, con_pos, con_frame = contacts.count, contacts.geom, contacts.pos, contacts.frame
    con_dim, con_friction, con_efc = contacts.dim, contacts.friction, contacts.efc_address
    rel = np.empty(6)
    normal_vel = np.empty(12)
    for c in range(ncon):
        adr = con_efc[c]
        if adr < 0:
            continue
        t = efc_type[adr]
        if t == frictionless:
            n_rows = 1
        elif t == pyramidal:
            n_rows = 2 * (con_dim[c] - 1)
        elif t == elliptic:
            n_rows = con_dim[c]
        else:
            continue
        touched = False
        rel[:] = 0.0
        for side in range(2):
            g = con_geom[c, side]
            if g < 0:
                continue
            b = geom_body[g]
            if not moving[b]:
                continue
            touched = True
            sign = 1.0 if side == 1 else -1.0
            rx = con_pos[c, 0] - xpos[b, 0]
            ry = con_pos[c, 1] - xpos[b, 1]
            rz = con_pos[c, 2] - xpos[b, 2]
            wx, wy, wz = body_vel[b, 3], body_vel[b, 4], body_vel[b, 5]
            vx = body_vel[b, 0] + wy * rz - wz * ry
            vy = body_vel[b, 1] + wz * rx - wx * rz
            vz = body_vel[b, 2] + wx * ry - wy * rx
            for k in range(3):
                f0, f1, f2 = con_frame[c, 3 * k], con_frame[c, 3 * k + 1], con_frame[c, 3 * k + 2]
                rel[k] += sign * (f0 * vx + f1 * vy + f2 * vz)
                rel[3 + k] += sign * (f0 * wx + f1 * wy + f2 * wz)
        if not touched and efc_margin[adr] <= 0.0:
            continue
        normal = t == pyramidal and efc_margin[adr] > 0.0 and efc_pos[adr] >= 0.0
        # A speculative contact approached slowly (by at most SETTLING sink in the step at its
        # normal velocity, a moving body's counted where it approaches) may be crossed by sink.
        vn = (0.5 * (efc_vel[adr] + efc_vel[adr + 1]) if t == pyramidal else efc_vel[adr]) + min(rel[0], 0.0)
        allow = sink if -vn * h <= SETTLING * sink else 0.0
        if normal:
            _normal_rows(jac, efc_vel, adr, n_rows, normal_vel)
        for q in range(n_rows):
            r = adr + q
            w = rel[0]
            if t == elliptic:
                w = rel[q]  # normal, slide along t1, t2, spin about n, roll about t1, t2
            elif t == pyramidal and not normal:
                # rows n + mu_k c_k, n - mu_k c_k; c: slide along t1, t2, spin about n, roll about t1, t2
                k = q // 2
                mu = con_friction[c, k]
                w += mu * rel[1 + k] if q % 2 == 0 else -mu * rel[1 + k]
            vel = (normal_vel[q] if normal else efc_vel[r]) + w
            if efc_margin[r] > 0.0:
                d = efc_pos[r]
                if d >= 0.0:
                    # The body is already posed for the end of the step: its own motion
                    # only counts where it comes closer (the next pose), never as room.
                    if rel[0] > 0.0:
                        vel -= rel[0]
                    efc_aref[r] = -((d + allow) / h + vel) / h
                else:
                    efc_aref[r] = -efc_kbip[r, 1] * vel - efc_kbip[r, 0] * efc_kbip[r, 2] * d
            else:
                efc_aref[r] -= efc_kbip[r, 1] * w


@nb.njit(cache=True)
def speed_margins(v, a0, h, rod_of_place, chosen, static, room, sink, flexes, flex_margin):
    """Each chosen rod's contact margin [m], flex_margin[flexes[rod]] (MuJoCo's model, out),
    set to max(static, room h |v + h a0|) over its free vertices (their rod rod_of_place
    (n_places,)), the second term left out where the travel h |v + h a0| is at most
    ``sink`` [m]; v, a0 (3 n_places,) [m/s, m/s^2]; chosen (n_rods,) bool. Returns whether
    any margin is > 0."""
    fastest = np.zeros(len(flexes))
    for p in range(len(rod_of_place)):
        rod = rod_of_place[p]
        if not chosen[rod]:
            continue
        sx = v[3 * p] + h * a0[3 * p]
        sy = v[3 * p + 1] + h * a0[3 * p + 1]
        sz = v[3 * p + 2] + h * a0[3 * p + 2]
        fastest[rod] = max(fastest[rod], sx * sx + sy * sy + sz * sz)
    any_margin = static > 0.0
    for rod in range(len(flexes)):
        if chosen[rod]:
            travel = h * np.sqrt(fastest[rod])
            margin = max(static, room * travel if travel > sink else 0.0)
            flex_margin[flexes[rod]] = margin
            any_margin = any_margin or margin > 0.0
    return any_margin
