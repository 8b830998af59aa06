"""Contacts excluded after MuJoCo's collision: between a rod's end edges and bodies (a cable
model's contact exclude), and between nearby edges of one thick rod (:func:`self_reach`).

A MuJoCo 3.x cable model writes ``<exclude body1="B_last" body2="gripper"/>`` so that the
cable's last segment does not collide with what holds it. derods' rod collides as a flex,
and MuJoCo's body exclusion does not reach a flex's elements (measured: an exclude between
a rod's vertex bodies and a box leaves every edge's contacts). So the world marks those
contacts itself once MuJoCo's collision has found them (``mjContact.exclude``, which
MuJoCo's constraint builder skips) and has MuJoCo build the rows again
(``mj_makeConstraint``, ``mj_island``, ``mj_projectConstraint``: the same state as its
position stage would leave, bit for bit, measured on MuJoCo 4.0.1 and 3.17).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np


def self_reach(radius: float, edge_lengths: np.ndarray) -> int:
    """The largest gap j - i between edges i < j of one rod (radius [m], rest edge lengths
    [m]) whose contact is the rod's own tube and not a fold of it: any edges closer along
    the rod than pi r. A tube of radius r folded back on itself (a hairpin whose inner
    surface closes to a line) touches itself first across pi r of its centreline, so points
    nearer than that along the rod cannot touch; two edges g apart are at least g - 1
    shortest edges apart. MuJoCo leaves out only neighbours (gap 1); a rod with r >= l / 2
    (the pile's 1 cm edges of r = 5 mm) also touches edges two apart while straight, and
    every bend pushes them into each other: a stiffness the rod does not have."""
    shortest = float(np.min(edge_lengths))
    return max(1, math.ceil(math.pi * radius / shortest + 1.0) - 1)


class SelfReach(NamedTuple):
    """Self-contacts of rod ``rod`` (``n_edges`` edges, ``closed`` a ring) between edges at
    most ``reach`` apart (:func:`self_reach`) are left out."""

    rod: str
    reach: int
    n_edges: int
    closed: bool


class ExcludedPair(NamedTuple):
    """Contacts between the edges ``elements`` of rod ``rod`` and the geoms of body
    ``body`` (a MuJoCo body name), or the edges ``other_elements`` of rod ``other_rod``."""

    rod: str
    elements: tuple
    body: str | None = None
    other_rod: str | None = None
    other_elements: tuple = ()


class Exclusions:
    """The excluded pairs of a compiled world, as flex, element and body ids, and the
    rods' self reaches (:class:`SelfReach`); called on a data whose position stage has
    run, it marks their contacts and rebuilds the rows. ``bool(exclusions)`` is False
    when there are none (the step then costs nothing more)."""

    def __init__(self, model: mujoco.MjModel, pairs: list[ExcludedPair], reaches: list[SelfReach] = ()):
        self.model = model
        flex = lambda name: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)  # noqa: E731
        # per flex: the self reach (0: none) and, for a ring, its edges (0: open)
        self._reach = np.zeros(model.nflex, dtype=np.int64)
        self._ring = np.zeros(model.nflex, dtype=np.int64)
        for r in reaches:
            self._reach[flex(r.rod)], self._ring[flex(r.rod)] = r.reach, r.n_edges if r.closed else 0
        # (flex, element, body or -1, other flex or -1, other element or -1), one per combination
        rows = []
        for p in pairs:
            f = flex(p.rod)
            if p.body is not None:
                b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, p.body)
                rows += [(f, e, b, -1, -1) for e in p.elements]
            else:
                g = flex(p.other_rod)
                rows += [(f, e, -1, g, o) for e in p.elements for o in p.other_elements]
        self._pairs = np.array(rows, dtype=np.int64).reshape(-1, 5)
        # mj_fwdPosition finds islands unless the model turns them off
        self._islands = not model.opt.disableflags & int(getattr(mujoco.mjtDisableBit, "mjDSBL_ISLAND", 0))

    def __bool__(self) -> bool:
        return len(self._pairs) > 0 or bool(self._reach.any())

    def __call__(self, d: mujoco.MjData) -> int:
        """Mark the excluded pairs' contacts of d and, if any, rebuild MuJoCo's constraint
        rows; returns how many contacts were marked."""
        if not d.ncon:
            return 0
        m, con, pairs = self.model, d.contact, self._pairs
        geom, flexes, elem = con.geom, con.flex, con.elem
        body = np.where(geom >= 0, m.geom_bodyid[np.maximum(geom, 0)], -1) if len(pairs) else None
        hit = np.zeros(d.ncon, dtype=bool)
        for a, b in ((0, 1), (1, 0)):
            for f, e, bd, g, o in pairs:
                mine = (flexes[:, a] == f) & (elem[:, a] == e)
                if bd >= 0:
                    hit |= mine & (body[:, b] == bd)
                else:
                    hit |= mine & (flexes[:, b] == g) & (elem[:, b] == o)
        f = flexes[:, 0]
        own = (f >= 0) & (f == flexes[:, 1])
        if own.any() and self._reach.any():
            gap = np.abs(elem[:, 0] - elem[:, 1])
            ring = self._ring[np.maximum(f, 0)]
            gap = np.where(ring > 0, np.minimum(gap, ring - gap), gap)
            hit |= own & (gap <= self._reach[np.maximum(f, 0)])
        hit &= con.exclude == 0
        n = int(hit.sum())
        if n:
            con.exclude[hit] = 1
            # MuJoCo's constraint builder skips an excluded contact without resetting its
            # row address: left, it would point at rows now another contact's (and past
            # nefc), where the rows' readers (the speculative correction, mj_contactForce)
            # read and write.
            con.efc_address[hit] = -1
            mujoco.mj_makeConstraint(m, d)
            if self._islands:
                mujoco.mj_island(m, d)
            mujoco.mj_projectConstraint(m, d)
        return n
