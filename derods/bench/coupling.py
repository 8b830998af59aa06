"""Bench case ``coupling``: a rod holding a free body, against the closed form.

A cantilever (clamped at (0, 0, 1) m along +x, no gravity) carries a free body (a small
sphere on a free joint) pinned to its tip; the body's mass is swept over ``MASS_RATIOS``
times the rod's. Started from the static tip-load shape (tip 1 % of L up), the pair
swings in its first mode, whose frequency is Euler-Bernoulli's for a beam with a tip
mass: beta L is the smallest root of

    1 + cos(bL) cosh(bL) + mu bL (cos(bL) sinh(bL) - sin(bL) cosh(bL)) = 0,   mu = m / (rho A L),

f = (bL)^2 / (2 pi) sqrt(alpha / (rho A L^4)) (mu = 0: the bare cantilever's 1.8751;
:func:`derods.reference.tip_mass_frequency`). The record per mass: ``measured`` the
frequency from the tip's zero crossings, ``reference`` the closed form, ``stable``. It
measures how the rod's force reaches the body: a held end's holder is solved together
with the rod (:mod:`derods.sim.holders`); applied one step late instead
(:class:`derods.sim.clamps.Reactions` alone, as before), every body of 1e-3 .. 1e3
times the rod's mass diverged at dt = 1e-2.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .. import shapes
from ..reference import tip_mass_frequency
from ..rod import Rod
from ..sim.divergence import DivergenceError
from ..sim.world import World
from .measures import StepClock, crossing_frequency, record, step_recording, tip_height

#: Body mass over rod mass.
MASS_RATIOS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)
#: The body: a sphere of this radius [m] (no collisions).
BOB_RADIUS = 0.01


def held_world(p, mass: float, joint_damping: float = 0.0) -> World:
    """The cantilever of ``p`` with a free body "bob" of ``mass`` [kg] pinned to its tip (its
    free joint damped by ``joint_damping`` [N s/m], 0 by default)."""
    return rod_and_body(p, "bob", "free", "pin", mass, joint_damping)


def rod_and_body(p, name: str, joint: str, end: str, mass: float, joint_damping: float = 0.0) -> World:
    """The rod of ``p`` along +x from (0, 0, 1) m, clamped to the world at its start, its end
    held (``end``: "pin" or "clamp") by a body ``name`` of ``mass`` [kg], a small sphere that
    touches nothing, on a free joint, a slide along the rod or a vertical hinge LEVER
    beyond the tip (``joint``: "free", "slide", "hinge") damped by ``joint_damping``; no
    gravity."""
    x = shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name=name, pos=x[-1])
    if joint == "slide":
        dof = body.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1.0, 0.0, 0.0])
    elif joint == "hinge":
        dof = body.add_joint(type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0.0, 0.0, 1.0], pos=[LEVER, 0.0, 0.0])
    else:
        dof = body.add_freejoint()
    dof.damping = [joint_damping, 0.0, 0.0]
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[BOB_RADIUS, 0, 0], mass=mass, contype=0,
                  conaffinity=0)
    world = World(spec, dt=p.dt, gravity=(0.0, 0.0, 0.0), mode=p.mode)
    world.add_rod(Rod(x, p.material), "rod", start="clamp", end=end, end_body=name)
    world.compile()
    return world


def _bend(world: World, x: np.ndarray, length: float) -> None:
    """The static tip-load shape w ~ s^2 (3 L - s), tip 1 % of L up, body moved along."""
    s = np.clip(x[:, 0], 0.0, None)
    shape = s**2 * (3 * length - s)
    bent = x.copy()
    bent[:, 2] += 0.01 * length * shape / shape[-1]
    bent[:2] = x[:2]  # the clamped edge stays
    m, d = world.model, world.data
    adr = m.jnt_qposadr[m.body("bob").jntadr[0]]
    d.qpos[adr:adr + 3] = bent[-1]
    mujoco.mj_kinematics(m, d)
    world.set_positions("rod", bent)


def coupling(p, periods: float = 3.0) -> list[dict]:
    """One record per body mass in MASS_RATIOS (see the module docstring)."""
    mat = p.material
    rod_mass = mat.line_density * p.length
    out = []
    for mu in MASS_RATIOS:
        ref = tip_mass_frequency(mat.alpha, mat.line_density, p.length, mu)
        world = StepClock(held_world(p, mu * rod_mass))
        rest = shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
        _bend(world, rest, p.length)
        n_steps = int(math.ceil((periods + 0.25) / ref / p.dt))
        z, stable, note, wall = step_recording(world, n_steps, tip_height)
        measured = crossing_frequency(z, p.dt) if stable else None
        if stable and measured is None:
            note = f"fewer than two upward crossings in {n_steps} steps"
        if stable and not np.all(np.isfinite(z)) or (stable and np.max(np.abs(z)) > 0.5 * p.length):
            stable, note = False, f"the tip left the swing: |z| up to {np.nanmax(np.abs(z)):.3g} m"
        out.append(record("coupling", p, world, measured if stable else None, ref, stable, wall, mass_ratio=mu,
                          body_mass=mu * rod_mass, note=note))
    return out


#: The held-body scenes of :func:`perturbed`: a clamped end on a body that slides along the
#: rod, on a free body, or on an arm that turns about a vertical hinge 0.1 m beyond the tip.
SCENES = ("slide", "free", "hinge")
#: The hinge scene's lever [m]: its axis passes this far beyond the rod's tip.
LEVER = 0.1
#: How far the energy of :func:`perturbed` may rise over its start (round-off and the
#: linearization's error; an unstable mode grows it by orders of magnitude).
ENERGY_TOLERANCE = 1.01
#: Body masses [kg] the stability sweep (benchmarks/bench_holders.py) takes.
SWEEP_MASSES = (1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4)


def clamped_world(p, scene: str, mass: float) -> World:
    """:func:`rod_and_body` with its end clamped to a body "holder" of ``mass`` [kg] on a
    slide along the rod ("slide"), a free joint ("free") or a hinge ("hinge")."""
    if scene not in SCENES:
        raise ValueError(f"scene must be one of {SCENES}, got {scene!r}")
    return rod_and_body(p, "holder", scene, "clamp", mass)


def perturbed(p, scene: str, mass: float, steps: int = 300, offset: float = 1e-6) -> dict:
    """Move the holder of :func:`clamped_world` by ``offset`` [m] (along each of its
    translations; the hinge's arm by that much at its lever) from rest and step: ``stable`` when nothing diverged and the energy
    (the rod's elastic energy and every body's kinetic energy) never rose above
    ENERGY_TOLERANCE times its start: nothing feeds the motion, backward Euler damps it,
    and an unstable mode grows exponentially. (The displacement is no measure: the stiff
    rod passes the clamp's local strain energy into softer modes of larger amplitude.)
    Returns {stable, peak [m] (largest displacement), energy (largest over the start),
    note}."""
    world = clamped_world(p, scene, mass)
    m, d = world.model, world.data
    adr = m.jnt_qposadr[m.body("holder").jntadr[0]]
    k = 3 if scene == "free" else 1
    unit = LEVER if scene == "hinge" else 1.0  # [m] per unit of the holder's coordinate
    rest = d.qpos[adr:adr + k].copy()
    d.qpos[adr:adr + k] += offset / unit
    mujoco.mj_kinematics(m, d)
    energy, peak, note = [], 0.0, ""
    mv = np.zeros(m.nv)
    try:
        for i in range(steps):
            mujoco.mj_mulM(m, d, mv, d.qvel)
            kinetic = 0.5 * float(d.qvel @ mv)
            world.step()  # its first stage evaluates the rods at the state the kinetic energy saw
            energy.append(float(np.sum(world._step.terms.energy)) + kinetic)
            peak = max(peak, unit * float(np.max(np.abs(d.qpos[adr:adr + k] - rest))))
            if not np.isfinite(peak) or energy[-1] > ENERGY_TOLERANCE * energy[0]:
                note = f"the energy rose {energy[-1] / energy[0]:.3g} times by step {i}"
                break
    except DivergenceError as err:
        note = str(err)
    return {"stable": not note, "peak": peak, "energy": max(energy) / energy[0] if energy else float("nan"),
            "note": note}
