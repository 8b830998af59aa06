"""Compiled mirror of :mod:`derods.sim.friction`: the anchors of the rods' sticking
contacts, carried from step to step, and the tangential slip they add to MuJoCo's
pyramidal rows, or to an elliptic contact's frictional rows."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np


class FlexContacts(NamedTuple):
    """MuJoCo's contacts (data.contact) as the anchors read them: count (ncon); per contact
    geom, flex, elem, vert (ncon, 2) (-1 where a side is not one), pos (ncon, 3) [m], frame
    (ncon, 9), dim, friction (ncon, 5), efc_address."""

    count: int
    geom: np.ndarray
    flex: np.ndarray
    elem: np.ndarray
    vert: np.ndarray
    pos: np.ndarray
    frame: np.ndarray
    dim: np.ndarray
    friction: np.ndarray
    efc_address: np.ndarray


class Kinds(NamedTuple):
    """The contact rows anchors act on: MuJoCo's pyramidal and elliptic constraint types,
    and the model's impratio (an elliptic cone's frictional rows' weights over its normal's)."""

    pyramidal: int
    elliptic: int
    impratio: float


class Tables(NamedTuple):
    """The model's tables a contact side is read from: geom_body (ngeom + 1,), elem_adr,
    vert_adr (nflex + 1,) (MuJoCo's flex_elemadr, flex_vertadr), vert_body (nflexvert + 1,),
    each with one entry more, read by a side that is not of its kind; elem_bodies
    (max(nflexelem, 1), 2) (a 1D element's vertex bodies, :func:`derods.sim.layout.
    element_bodies`), read for element sides only; n_geom, n_elem: MuJoCo's ngeom, nflexelem."""

    geom_body: np.ndarray
    elem_adr: np.ndarray
    vert_adr: np.ndarray
    elem_bodies: np.ndarray
    vert_body: np.ndarray
    n_geom: int
    n_elem: int


class Anchors(NamedTuple):
    """The anchored contacts of a step (k of them), sorted by key, replaced whole, never
    changed in place (so a failed step is undone by keeping the last one).

    keys (k,): each contact's two sides as one number; contact (k,): its index in
    MuJoCo's ``data.contact`` this step; body (k, 2, 2), weight (k, 2, 2), local (k, 2, 2,
    3) [m]: each side's material point as up to two terms, weight times (a body's position
    plus the point in its frame); start (k, 2, 3) [m]: where each side's point was when
    the contact was anchored; slip (k, 3) [m]: side 1's point relative to side 0's since;
    age (k,): the steps it has been there without sliding."""

    keys: np.ndarray
    contact: np.ndarray
    body: np.ndarray
    weight: np.ndarray
    local: np.ndarray
    start: np.ndarray
    slip: np.ndarray
    age: np.ndarray


@nb.njit(cache=True)
def no_anchors():
    """No anchored contact."""
    return Anchors(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 2, 2), dtype=np.int64),
                   np.zeros((0, 2, 2)), np.zeros((0, 2, 2, 3)), np.zeros((0, 2, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64))


@nb.njit(cache=True)
def _side_id(g, f, e, v, n_geom, n_elem, elem_adr, vert_adr):
    """A number for a contact side (MuJoCo's geom, flex, elem, vert of it): its geom, else
    its flex element (after the geoms), else its flex vertex (after those)."""
    if g >= 0:
        return g
    if e >= 0:
        return n_geom + elem_adr[f] + e
    return n_geom + n_elem + vert_adr[f] + v


@nb.njit(cache=True)
def _new_side(g, f, e, v, p, geom_body, elem_adr, elem_bodies, vert_adr, vert_body, xpos, xmat, body, weight, local):
    """A contact side (MuJoCo's geom, flex, elem, vert of it) as the material point at p
    (3,) [m], into body (2,), weight (2,), local (2, 3): a body's point p fixed in its
    frame, or a flex element's vertices weighted by where p falls along the element, or a
    flex vertex. (Called once per new contact side, with plain arrays: a named tuple
    passed to a helper costs a reference count per field at every call.)"""
    local[:] = 0.0
    weight[1] = 0.0
    weight[0] = 1.0
    if g >= 0:
        b = geom_body[g]
        body[0], body[1] = b, b
        for i in range(3):
            acc = 0.0
            for j in range(3):
                acc += xmat[b, 3 * j + i] * (p[j] - xpos[b, j])
            local[0, i] = acc
        return
    if e >= 0:
        b0, b1 = elem_bodies[elem_adr[f] + e, 0], elem_bodies[elem_adr[f] + e, 1]
        num, den = 0.0, 0.0
        for i in range(3):
            edge = xpos[b1, i] - xpos[b0, i]
            num += (p[i] - xpos[b0, i]) * edge
            den += edge * edge
        u = min(max(num / den, 0.0), 1.0) if den > 0.0 else 0.0
        body[0], body[1] = b0, b1
        weight[0], weight[1] = 1.0 - u, u
        return
    b = vert_body[vert_adr[f] + v]
    body[0], body[1] = b, b


@nb.njit(cache=True)
def _point(xpos, xmat, body, weight, local, q, s, out):
    """Side s of anchor q's material point now [m] (into out (3,))."""
    for i in range(3):
        out[i] = 0.0
    for t in range(2):
        w = weight[q, s, t]
        if w == 0.0:
            continue
        b = body[q, s, t]
        for i in range(3):
            acc = xpos[b, i]
            for j in range(3):
                acc += xmat[b, 3 * i + j] * local[q, s, t, j]
            out[i] += w * acc


@nb.njit(cache=True)
def anchor(con, tables, last, efc_type, efc_kbip, efc_aref, xpos, xmat, kinds, max_slip, min_age):
    """This step's anchors (:class:`Anchors`, returned) from the last step's ``last``: every
    pyramidal or elliptic contact of a rod (a flex side, dim >= 3) keeps its anchor if it was there
    (same two sides) and slipped less than ``max_slip`` [m] since the last step (else it
    slides, and is anchored again where it is, as a new one is); once it has been there
    ``min_age`` steps (until then it is anchored again where it is every step), its
    friction pairs' reference accelerations (``efc_aref``, in place) get the slip since the
    anchor: for pair j (rows J_n +- mu_j J_tj), aref -= +-K imp mu_j (s . t_j), s the side 1
    point's motion relative to the side 0 point's (K, imp from ``efc_kbip``); an elliptic
    contact's frictional row j, aref -= K imp (s . t_j) / impratio, a spring as stiff as its
    normal row's (its weight is the normal's times mu_j^2 / mu^2, mu^2 = mu_1^2 / impratio).
    kinds: (MuJoCo's pyramidal and elliptic contact types, impratio)."""
    n = con.count
    geom, flex, elem, vert, pos = con.geom, con.flex, con.elem, con.vert, con.pos
    n_geom, n_elem, elem_adr, vert_adr = tables.n_geom, tables.n_elem, tables.elem_adr, tables.vert_adr
    geom_body, elem_bodies, vert_body = tables.geom_body, tables.elem_bodies, tables.vert_body
    keys = np.empty(n, dtype=np.int64)
    which = np.empty(n, dtype=np.int64)
    k = 0
    for c in range(n):
        adr = con.efc_address[c]
        if con.dim[c] < 3 or adr < 0 or (efc_type[adr] != kinds.pyramidal and efc_type[adr] != kinds.elliptic):
            continue
        if flex[c, 0] < 0 and flex[c, 1] < 0:
            continue
        keys[k] = (_side_id(geom[c, 0], flex[c, 0], elem[c, 0], vert[c, 0], n_geom, n_elem, elem_adr, vert_adr)
                   * (1 << 32)
                   + _side_id(geom[c, 1], flex[c, 1], elem[c, 1], vert[c, 1], n_geom, n_elem, elem_adr, vert_adr))
        which[k] = c
        k += 1
    order = np.argsort(keys[:k])
    keys, which = keys[:k][order], which[:k][order]
    body, weight = np.empty((k, 2, 2), dtype=np.int64), np.empty((k, 2, 2))
    local, start, slip = np.empty((k, 2, 2, 3)), np.empty((k, 2, 3)), np.zeros((k, 3))
    age = np.zeros(k, dtype=np.int64)
    last_keys, last_body, last_weight, last_local, last_start = last.keys, last.body, last.weight, last.local, last.start
    last_slip, last_age = last.slip, last.age
    frame, friction, efc_address = con.frame, con.friction, con.efc_address
    p0 = np.empty(3)
    p1 = np.empty(3)
    at = 0  # both key lists are sorted: one merge
    n_last = len(last_keys)
    for q in range(k):
        c = which[q]
        while at < n_last and last_keys[at] < keys[q]:
            at += 1
        if at < n_last and last_keys[at] == keys[q]:
            for s in range(2):  # element by element: numba's slice copies cost ~0.1 us each
                for t in range(2):
                    body[q, s, t] = last_body[at, s, t]
                    weight[q, s, t] = last_weight[at, s, t]
                    for i in range(3):
                        local[q, s, t, i] = last_local[at, s, t, i]
                for i in range(3):
                    start[q, s, i] = last_start[at, s, i]
            age[q] = last_age[at] + 1
        else:
            for s in range(2):
                _new_side(geom[c, s], flex[c, s], elem[c, s], vert[c, s], pos[c], geom_body, elem_adr, elem_bodies,
                          vert_adr, vert_body, xpos, xmat, body[q, s], weight[q, s], local[q, s])
                _point(xpos, xmat, body, weight, local, q, s, p0)
                for i in range(3):
                    start[q, s, i] = p0[i]
            continue  # anchored now: no slip yet
        _point(xpos, xmat, body, weight, local, q, 0, p0)
        _point(xpos, xmat, body, weight, local, q, 1, p1)
        moved = 0.0
        for i in range(3):
            slip[q, i] = (p1[i] - start[q, 1, i]) - (p0[i] - start[q, 0, i])
            moved += (slip[q, i] - last_slip[at, i]) ** 2
        if moved > max_slip * max_slip or age[q] < min_age:
            # sliding (then its age starts again), or not yet resting: anchored again where
            # it is, no spring this step
            if moved > max_slip * max_slip:
                age[q] = 0
            for i in range(3):
                start[q, 0, i] = p0[i]
                start[q, 1, i] = p1[i]
                slip[q, i] = 0.0
            continue
        adr = efc_address[c]
        kimp = efc_kbip[adr, 0] * efc_kbip[adr, 2]
        for j in range(1, 3):
            s_j = 0.0
            for i in range(3):
                s_j += slip[q, i] * frame[c, 3 * j + i]
            if efc_type[adr] == kinds.elliptic:
                efc_aref[adr + j] -= kimp * s_j / kinds.impratio
                continue
            shift = kimp * friction[c, j - 1] * s_j
            efc_aref[adr + 2 * (j - 1)] -= shift
            efc_aref[adr + 2 * (j - 1) + 1] += shift
    return Anchors(keys, which, body, weight, local, start, slip, age)


@nb.njit(cache=True)
def reanchor_slipping(anchors, con, efc_type, efc_force, efc_pos, xpos, xmat, kinds, slip_tol):
    """The anchors (a new :class:`Anchors`) with the contacts that slip anchored again where
    they are: those whose solved force (``efc_force``) lies on the cone's boundary: a
    pyramid's, all of it in one row of each pair (sum_j |f+ - f-| >= (1 - slip_tol) sum f);
    an elliptic cone's, |(f_j / mu_j)_j| >= (1 - slip_tol) f_n, whose anchor is instead
    moved to where its spring pulls with the cone's limit (efc_pos: the rows' penetration
    [m]). con: MuJoCo's contacts (:class:`FlexContacts`); kinds: as :func:`anchor`'s."""
    k = len(anchors.keys)
    start = anchors.start.copy()
    slip = anchors.slip.copy()
    age = anchors.age.copy()
    contact, body, weight, local = anchors.contact, anchors.body, anchors.weight, anchors.local
    p = np.empty(3)
    for q in range(k):
        c = contact[q]
        adr = con.efc_address[c]
        total, spent = 0.0, 0.0
        if efc_type[adr] == kinds.elliptic:
            total = efc_force[adr]
            for j in range(1, con.dim[c]):
                spent += (efc_force[adr + j] / con.friction[c, j - 1]) ** 2
            spent = np.sqrt(spent)
        else:
            for j in range(1, con.dim[c]):
                plus, minus = efc_force[adr + 2 * (j - 1)], efc_force[adr + 2 * (j - 1) + 1]
                total += plus + minus
                if j <= 2:  # the sliding pairs; torsional and rolling pairs only carry normal force here
                    spent += abs(plus - minus)
        if not (total > 0.0 and spent >= (1.0 - slip_tol) * total):
            continue
        if efc_type[adr] == kinds.elliptic and efc_pos[adr] < 0.0:
            # Dragged along, not let go: the anchor follows to where its spring pulls with
            # the cone's limit mu_1 f_n, which it reaches at a tangential slip of mu_1 times
            # the penetration (the spring as stiff as the normal row's, see anchor), and the
            # contact keeps its age: it holds again the step the pull falls inside the cone.
            st2 = 0.0
            sn = 0.0
            for i in range(3):
                sn += slip[q, i] * con.frame[c, i]
            for i in range(3):
                st2 += (slip[q, i] - sn * con.frame[c, i]) ** 2
            limit = con.friction[c, 0] * -efc_pos[adr]
            rho = min(1.0, limit / np.sqrt(st2)) if st2 > 0.0 else 1.0
            for i in range(3):
                start[q, 1, i] += (1.0 - rho) * slip[q, i]
                slip[q, i] *= rho
            continue
        for s in range(2):
            _point(xpos, xmat, body, weight, local, q, s, p)
            for i in range(3):
                start[q, s, i] = p[i]
                slip[q, i] = 0.0
        age[q] = 0
    return Anchors(anchors.keys, contact, body, weight, local, start, slip, age)
