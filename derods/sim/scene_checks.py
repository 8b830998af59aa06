"""What a compiled scene may get wrong before it runs, in words.

A World and the ``derods drop`` command ask the same questions here, so they say the
same: is the step too long for the fall (a rod falling from where it starts moves more
than half its length, or more than a thin obstacle is thick, in one step at impact), does
a rod start inside an obstacle, is a rod held at both ends longer than its rest length?
A World warns (:class:`derods.SceneWarning`, as a user may mean it); the command line
refuses the first and notes the others.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

#: A rod held at both ends whose initial shape is longer than its rest length by more than
#: this [relative] is reported: it starts under tension it cannot relax.
STRETCH_TOL = 1e-3


def _fall(model: mujoco.MjModel, data: mujoco.MjData, tops: list) -> tuple[float, float, float]:
    """(height [m] of the highest rod above the lowest geom, speed [m/s] at impact, g [m/s^2])."""
    floor = float(np.min(data.geom_xpos[:, 2])) if model.ngeom else 0.0
    top = max(tops)
    g = float(np.linalg.norm(model.opt.gravity))
    return top - floor, math.sqrt(2.0 * g * max(top - floor, 0.0)), g


def fall_step(model: mujoco.MjModel, data: mujoco.MjData, tops: list, lengths: list) -> str | None:
    """The step's refusal in words if a rod falling from where it starts would move more than
    half its length in one step at impact (no contact can hold that: it passes through
    obstacles within a step), else None. tops: each rod's highest vertex [m]; lengths: each
    rod's length [m]."""
    height, v, _ = _fall(model, data, tops)
    dt = model.opt.timestep
    half = 0.5 * min(lengths)
    if v * dt > half:
        return (f"dt {dt:g} s lets a rod falling from {height:.2g} m move {v * dt:.3g} m in one step "
                f"at impact ({v:.2g} m/s), more than half its length ({half:.3g} m): no contact can hold; "
                f"use dt <= {half / v:.3g} s (dt <= {0.1 * half / v:.2g} s films it well)")
    return None


def thin_geoms(model: mujoco.MjModel, data: mujoco.MjData, tops: list, radius: float) -> list:
    """Obstacles thinner than a falling rod's travel in one step at impact (plus the rod's
    diameter), in words: a rod may pass through them without a contact ever being found.
    radius: the thinnest rod's radius [m]."""
    _, v, _ = _fall(model, data, tops)
    dt = model.opt.timestep
    out = []
    for g in range(model.ngeom):
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        if model.geom_type[g] in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD):
            continue  # unbounded below: nothing to pass through
        thick = 2.0 * float(np.min(model.geom_aabb[g, 3:]))
        if v * dt > thick + 2.0 * radius:
            name = model.geom(g).name or f"geom {g}"
            out.append(f"{name} is {1000 * thick:.3g} mm thick and a rod falling onto it moves {1000 * v * dt:.3g} mm "
                       f"in one step at impact (dt {dt:g} s, {v:.2g} m/s): it may pass through without touching it; "
                       f"use dt <= {(thick + 2.0 * radius) / v:.2g} s")
    return out


def starts_inside(model: mujoco.MjModel, data: mujoco.MjData, names: list, radii: list,
                  holders: list | None = None) -> list:
    """Rods that start inside an obstacle (a contact deeper than their radius), in words,
    from the contacts of MuJoCo's last forward pass. names, radii [m]: the rods'.
    holders: for each rod, the ids of the bodies holding its ends (a rod's end sits in
    its holder by design), or None."""
    out = []
    for i, (name, r) in enumerate(zip(names, radii)):
        flex = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)
        own = set(holders[i]) if holders else set()
        deepest, geom = 0.0, None
        for c in data.contact[: data.ncon]:
            if flex in (c.flex[0], c.flex[1]) and -c.dist > max(deepest, r):
                other = c.geom[0] if c.geom[0] >= 0 else c.geom[1]
                if other >= 0 and int(model.geom_bodyid[other]) in own:
                    continue
                deepest = -c.dist
                geom = model.geom(other).name or f"geom {other}" if other >= 0 else "another rod"
        if geom is not None:
            out.append(f"rod {name!r} starts inside {geom} ({1000 * deepest:.1f} mm deep, more than its radius "
                       f"{1000 * r:g} mm); it will be pushed out violently or stay stuck: move the scene's 'drop' "
                       "site or raise it")
    return out


def stretched(entries) -> dict:
    """Rods held at both ends whose initial shape is longer than their rest length by more
    than STRETCH_TOL: {index: relative excess length}. entries: the world's rods
    (:class:`derods.sim.layout.RodEntry`)."""
    out = {}
    for i, e in enumerate(entries):
        if e.rod.closed or e.start == "free" or e.end == "free":
            continue
        length = float(np.sum(np.linalg.norm(np.diff(e.x0, axis=0), axis=1)))
        excess = length / float(e.rod.length) - 1.0
        if excess > STRETCH_TOL:
            out[i] = excess
    return out


def stretched_words(entries, excess: dict) -> list:
    """:func:`stretched`'s rods in words."""
    return [f"rod {entries[i].name!r} is held at both ends and starts {100 * x:.3g} % longer than its rest length "
            "(x is longer than rest_x): it starts under a tension it cannot relax, which a stiff rod turns into a "
            "violent snap; start it at its rest shape, hold one end only, or give it a rest shape as long as x"
            for i, x in excess.items()]
