"""Contacts excluded between a rod's end edges and bodies (a cable model's contact exclude).

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

from typing import NamedTuple

import mujoco
import numpy as np


class ExcludedPair(NamedTuple):
    """Contacts between the edges ``elements`` of rod ``rod`` and the geoms of body
    ``body`` (a MuJoCo body name), or the edges ``other_elements`` of rod ``other_rod``."""

    rod: str
    elements: tuple
    body: str | None = None
    other_rod: str | None = None
    other_elements: tuple = ()


class Exclusions:
    """The excluded pairs of a compiled world, as flex, element and body ids; called on a
    data whose position stage has run, it marks their contacts and rebuilds the rows.
    ``bool(exclusions)`` is False when there are none (the step then costs nothing more)."""

    def __init__(self, model: mujoco.MjModel, pairs: list[ExcludedPair]):
        self.model = model
        flex = lambda name: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)  # noqa: E731
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
        return len(self._pairs) > 0

    def __call__(self, d: mujoco.MjData) -> int:
        """Mark the excluded pairs' contacts of d and, if any, rebuild MuJoCo's constraint
        rows; returns how many contacts were marked."""
        if not d.ncon:
            return 0
        m, con, pairs = self.model, d.contact, self._pairs
        geom, flexes, elem = con.geom, con.flex, con.elem
        body = np.where(geom >= 0, m.geom_bodyid[np.maximum(geom, 0)], -1)
        hit = np.zeros(d.ncon, dtype=bool)
        for a, b in ((0, 1), (1, 0)):
            for f, e, bd, g, o in pairs:
                mine = (flexes[:, a] == f) & (elem[:, a] == e)
                if bd >= 0:
                    hit |= mine & (body[:, b] == bd)
                else:
                    hit |= mine & (flexes[:, b] == g) & (elem[:, b] == o)
        hit &= con.exclude == 0
        n = int(hit.sum())
        if n:
            con.exclude[hit] = 1
            mujoco.mj_makeConstraint(m, d)
            if self._islands:
                mujoco.mj_island(m, d)
            mujoco.mj_projectConstraint(m, d)
        return n
