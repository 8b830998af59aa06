"""The contacts of a world's rods, one record each, with the forces the last step applied.

MuJoCo lists a rod's contacts as those of its collision flex: a vertex or an edge (element)
against a geom, or against another flex. derods writes the row forces it solved into
MuJoCo's ``efc_force`` (:mod:`derods.sim.forward`), so ``mj_contactForce`` reads what derods
applied; :func:`rod_contacts` turns each contact into world-frame vectors on the rod.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np


class RodContact(NamedTuple):
    """One contact of a rod in the last step (forces in the world frame, on the rod).

    rod: the rod's name. vertex, edge: the rod's vertex or edge in contact (the other -1;
    MuJoCo collides a flex by vertices against planes and by edges elsewhere). body: the
    MuJoCo body touched, or -1 against a rod; geom: its geom (-1 against a rod).
    other_rod, other_vertex, other_edge: the rod touched (itself in self-contact; None, -1,
    -1 against a body). position [m] (3,): MuJoCo's contact point. normal (3,): unit, from
    what it touches towards the rod. normal_force [N] (>= 0 pushing apart), friction [N] (3,):
    the tangential force on the rod. depth [m]: how far they overlap (>= 0 when touching).
    """

    rod: str
    vertex: int
    edge: int
    body: int
    geom: int
    other_rod: str | None
    other_vertex: int
    other_edge: int
    position: np.ndarray
    normal: np.ndarray
    normal_force: float
    friction: np.ndarray
    depth: float


def rod_contacts(model: mujoco.MjModel, data: mujoco.MjData, flex_rod: dict) -> list[RodContact]:
    """Every contact of ``data`` that involves a rod (``flex_rod``: flex id -> rod name) and
    entered the step's constraints (MuJoCo left out those in a margin's gap or excluded),
    seen from the rod (for rod-rod contacts, from the first side's)."""
    out, f6 = [], np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        if c.exclude != 0 or c.efc_address < 0:
            continue
        sides = [k for k in (1, 0) if c.flex[k] in flex_rod]
        if not sides:
            continue
        k = sides[0]  # the rod's side (the second's, if both are rods)
        mujoco.mj_contactForce(model, data, i, f6)
        frame = c.frame.reshape(3, 3)
        force = frame.T @ f6[:3] * (1.0 if k == 1 else -1.0)  # MuJoCo's force acts on side 2
        normal = frame[0] * (1.0 if k == 1 else -1.0)
        o = 1 - k
        rod_other = flex_rod.get(int(c.flex[o])) if c.flex[o] >= 0 else None
        out.append(RodContact(
            rod=flex_rod[int(c.flex[k])], vertex=int(c.vert[k]), edge=int(c.elem[k]),
            body=int(model.geom_bodyid[c.geom[o]]) if c.geom[o] >= 0 else -1, geom=int(c.geom[o]),
            other_rod=rod_other, other_vertex=int(c.vert[o]) if rod_other else -1,
            other_edge=int(c.elem[o]) if rod_other else -1, position=c.pos.copy(), normal=normal,
            normal_force=float(f6[0]), friction=force - float(f6[0]) * normal, depth=float(-c.dist)))
    return out
