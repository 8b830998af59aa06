"""Benchmark cases, each defined once: ``python -m derods bench CASE``.

Every case builds its scene from a :class:`derods.bench.params.CaseParams`, runs it, and
returns records (dicts, one JSON object per line on the command line) with the fields of
:func:`derods.bench.measures.record`. Beside the cases here: ``extreme``
(:mod:`derods.bench.extreme`) and ``coupling`` (:mod:`derods.bench.coupling`); the command
that runs one by name: :mod:`derods.bench.command`.

Cases:

* ``cantilever``: a rod clamped at one end, horizontal, sags under gravity
  until it rests; measured: tip drop [m]; reference: the inextensible
  elastica (:func:`derods.reference.cantilever_elastica`).
* ``frequency``: the same rod without gravity released from a small bend;
  measured: first bending frequency [Hz] from the tip's zero crossings;
  reference: 1.8751^2 / (2 pi) sqrt(alpha / (rho A L^4)).
* ``michell``: a naturally straight ring (circumference L) with imposed total
  twist Theta, released from a slightly bent circle without gravity; Theta is
  bisected between planar (the bend dies out) and buckled (it grows);
  measured: the critical twist [rad]; reference: Michell's 2 pi sqrt(3) alpha / beta.
* ``circle``: a rod clamped at one end, without gravity, under an end couple
  M = 2 pi alpha / L on its last edge; measured: the distance from the tip to
  the clamp over L (0 for a closed circle); reference: 0.
* ``twist``: a straight rod clamped at one end to the world and at the other
  to a body on a hinge along the rod, which a position servo turns k = 2 times;
  measured: the torque the servo needs to hold it [N m]; reference: beta Theta / L
  with Theta the angle the body turned (the servo lags its target by torque / kp).
* ``drop``: a free rod dropped from 0.5 m, flat and tilted by 0.3 rad, onto
  the floor and across the edge of a box (mjcf/floor.xml, mjcf/box.xml);
  measured: the deepest penetration [m] once the impact is over (from 0.5 s
  after first contact); reference: the rod radius, which it must stay below;
  the rod must also come to rest (speed below 1 mm/s) within 3 s.
"""

from __future__ import annotations

import dataclasses
import math
import time

import mujoco
import numpy as np

from .. import reference, shapes
from ..rod import Rod
from ..sim.divergence import DivergenceError
from ..sim.world import World
from ..twist import TwistBoundary
from . import native
from .backends import RodSimulator
from .measures import (StepClock, clamp_reaction, crossing_frequency, max_strain, median_step_us, out_of_plane,
                       record, step_recording, swing_amplitudes, tip_height)
from .params import CaseParams

#: A dropped rod is at rest when no vertex moves faster than this [m/s].
REST_SPEED = 1e-3
#: A ring out of its plane by more than this times its radius has buckled (a buckled ring
#: leaves it by order R; the perturbation is 1e-3 R).
BUCKLED = 0.05
#: A cantilever has settled when no vertex moves faster than this times its length [1/s].
SETTLE_SPEED = 1e-5


def _first_mode_rate(p: CaseParams) -> float:
    """Angular frequency [rad/s] of the slowest mode: bending, or the rod as a pendulum."""
    mat = p.material
    w1 = 2 * math.pi * reference.cantilever_frequency(mat.alpha, mat.line_density, p.length)
    return max(w1, math.sqrt(p.gravity / p.length) if p.gravity else 0.0)


def cantilever(p: CaseParams, max_time: float = 30.0) -> list[dict]:
    """Static tip drop of a horizontal cantilever under its weight, against the elastica."""
    mat = p.material
    ref = reference.cantilever_elastica(mat.line_density * p.gravity, p.length, mat.alpha)["tip_drop"]
    # Mass-proportional damping at 0.7 of critical on the slowest mode settles it fastest.
    world = StepClock(p.build.cantilever(p, p.gravity, 1.4 * _first_mode_rate(p))[0])
    chunk = max(1, int(round(0.1 / p.dt)))
    t0 = time.perf_counter()
    stable, measured, note = True, None, ""
    try:
        while world.time < max_time:
            world.step(chunk)
            if np.max(np.abs(world.velocities())) < SETTLE_SPEED * p.length:
                break
        measured = 1.0 - float(world.positions()[-1, 2])
    except DivergenceError as err:
        stable, note = False, str(err)
    wall = time.perf_counter() - t0
    settled = stable and np.max(np.abs(world.velocities())) < SETTLE_SPEED * p.length
    return [record("cantilever", p, world, measured, ref, stable, wall, settled=bool(settled),
                   note=note, **clamp_reaction(world, stable))]


def frequency(p: CaseParams, periods: int = 4) -> list[dict]:
    """First bending frequency of a clamped-free rod, no gravity, against Euler-Bernoulli."""
    mat = p.material
    ref = reference.cantilever_frequency(mat.alpha, mat.line_density, p.length)
    world, rest_x = p.build.cantilever(p, 0.0, 0.0)
    world = StepClock(world)
    # Start from the static shape under a uniform load (97 % first mode), tip at 1 % of L,
    # keeping the clamped edge straight.
    s = np.clip(rest_x[:, 0], 0.0, None)
    shape = s**2 * (6 * p.length**2 - 4 * p.length * s + s**2)
    shape[:2] = 0.0
    x0 = rest_x.copy()
    x0[:, 2] += 0.01 * p.length * shape / shape[-1]
    world.set_positions(0, x0)
    z, stable, note, wall = step_recording(world, int(math.ceil(periods / ref / p.dt)), tip_height)
    measured = crossing_frequency(z, p.dt) if stable else None
    return [record("frequency", p, world, measured, ref, stable, wall, note=note)]


#: The free-free rod of the oscillation case is this many times the cantilever's length,
#: which puts its first mode (4.7300^2 / 1.8751^2 / 2.5^2 = 1.018 times the cantilever's)
#: at the same steps per period.
FREE_LENGTH = 2.5


def oscillation(p: CaseParams, periods: int = 10) -> list[dict]:
    """Numerical damping, on two geometries: the fraction of the amplitude kept per
    period (1 for an exact integrator; the geometric mean over ``periods`` periods of the
    peak-to-peak amplitude two turning points apart) and the frequency error against
    Euler-Bernoulli.

    clamped: an undamped cantilever released straight under gravity swings about its
    sagged shape (the tip's height). free: a free-free rod FREE_LENGTH times as long, no
    gravity, started at rest in its first mode (ends at 1 % of L; an end's height above
    the rod's mean). The cable sets shapes only when clamped: it runs the first alone."""
    mat = p.material
    f1 = reference.cantilever_frequency(mat.alpha, mat.line_density, p.length)
    world = StepClock(p.build.cantilever(p, p.gravity, 0.0)[0])
    out = [_swing("clamped", p, world, f1, periods, lambda x: x[-1, 2])]
    if p.backend != "cable":
        length = FREE_LENGTH * p.length
        f_free = reference.free_free_frequency(mat.alpha, mat.line_density, length)
        free = dataclasses.replace(p, gravity=0.0, length=length)
        x = shapes.straight(length, p.n_edges, start=(0.0, 0.0, 1.0))
        world = StepClock(p.build.free_rod(free, x, None, 0.0))
        x0 = x.copy()
        x0[:, 2] += 0.01 * length * reference.free_free_mode(x[:, 0], length)
        world.set_positions(0, x0)
        out.append(_swing("free", p, world, f_free, periods, lambda x: x[-1, 2] - x[:, 2].mean(),
                          rod_length=length))
    return out


def _swing(variant: str, p: CaseParams, world, f1: float, periods: int, height, **extra) -> dict:
    """Step ``world`` for ``periods`` + 1/2 periods of f1 [Hz], recording height(positions)
    [m]; the oscillation record of what it kept (with ``extra`` fields)."""
    n_steps = int(math.ceil((periods + 0.5) / f1 / p.dt))
    z, stable, note, wall = step_recording(world, n_steps, height)
    measured, freq = None, None
    if stable:
        turns, amp = swing_amplitudes(z)
        if len(amp) >= 3 and amp[0] > 0:
            # turning points two apart are one period apart
            measured = float((amp[-1] / amp[0]) ** (2.0 / (len(amp) - 1))) if len(amp) % 2 else \
                float((amp[-2] / amp[0]) ** (2.0 / (len(amp) - 2)))
            freq = float(1.0 / (2.0 * np.mean(np.diff(turns)) * p.dt))
        else:
            note = f"{len(turns)} turning points in {n_steps} steps: the tip did not swing"
    return record("oscillation", p, world, measured, 1.0, stable, wall, variant=variant, frequency=freq,
                  frequency_ref=f1, frequency_error=None if freq is None else freq / f1 - 1.0, periods=periods,
                  note=note, **extra)


def drop(p: CaseParams, sim_time: float = 3.0, mass_damping: float = 2.0) -> list[dict]:
    """A free rod dropped flat and tilted onto the floor and across a box edge."""
    out = []
    for scene, tilt in (("floor", 0.0), ("floor", 0.3), ("box_edge", 0.0), ("box_edge", 0.3)):
        x = shapes.straight(p.length, p.n_edges, direction=(math.cos(tilt), 0.0, math.sin(tilt)))
        x -= x.mean(axis=0)
        # Centred 0.5 m above the floor; across the box, centred on its +x edge (x = 0.15).
        x += (0.15, 0.0, 0.7) if scene == "box_edge" else (0.0, 0.0, 0.5)
        world = StepClock(p.build.free_rod(p, x, "box" if scene == "box_edge" else scene, mass_damping))
        t0 = time.perf_counter()
        stable, note = True, ""
        first_contact, deepest_late, deepest, rest_at = None, 0.0, 0.0, None
        try:
            while world.time < sim_time - 0.5 * p.dt:
                world.step()
                d = world.data
                pen = max((-c.dist for c in d.contact[: d.ncon]), default=0.0)
                if d.ncon and first_contact is None:
                    first_contact = world.time
                deepest = max(deepest, pen)
                if first_contact is not None and world.time >= first_contact + 0.5:
                    deepest_late = max(deepest_late, pen)
                speed = float(np.max(np.abs(world.velocities())))
                if speed < REST_SPEED:
                    rest_at = world.time if rest_at is None else rest_at
                else:
                    rest_at = None
        except DivergenceError as err:
            stable, note = False, str(err)
        wall = time.perf_counter() - t0
        at_rest = stable and rest_at is not None
        rec = record("drop", p, world, deepest_late if stable else None, p.radius, stable, wall,
                     scene=scene, tilt=tilt, mass_damping=mass_damping, impact_penetration=deepest,
                     at_rest=at_rest, rest_time=rest_at, note=note)
        # Passing means staying below the radius: report the error against that bound.
        rec["rel_error"] = None if not stable else (deepest_late - p.radius) / p.radius
        out.append(rec)
    return out


def ring_buckles(p: CaseParams, total_twist: float, perturbation: float = 1e-3,
                 samples: list | None = None) -> tuple[bool, RodSimulator]:
    """Whether a twisted ring leaves its plane. The circle is bent out of plane by
    ``perturbation`` times its radius R (modes 2 and 3) and run for up to 40 bending
    times R^2 sqrt(rho A / alpha). It has buckled if it leaves its plane by more than
    ``BUCKLED`` R, or if it still grows: by more than 2 % from one window of 10 bending
    times to the next (near the threshold the growth is slow; a bound on the bend alone
    biases the threshold upwards). The bound, not a multiple of the perturbation, and
    the 2 % margin keep bounded responses from counting: the native rings settle out of
    plane by an amount that grows with the twist (flex: 1.25e-3 R at 0.8 of the
    threshold, n = 50, dt = 1e-2 s, even without perturbation). In the flex it is a
    time-stepping effect: unperturbed at half the threshold, n = 100, 4.7e-3 R after
    0.3 s at dt = 1e-2, 1.1e-4 R at 1e-3, 1.2e-6 R at 1e-4. samples: where the ring's
    StepClock puts its step times (:class:`derods.bench.measures.StepClock`)."""
    mat = p.material
    radius = p.length / (2 * math.pi)
    world = StepClock(p.build.twisted_ring(p, total_twist), samples)
    x = native.ring_vertices(p)
    phi = 2 * math.pi * np.arange(p.n_edges) / p.n_edges
    xp = x.copy()
    xp[:, 2] += perturbation * radius * (np.sin(2 * phi) + 0.1 * np.cos(3 * phi))
    world.set_positions(0, xp)
    t_bend = radius**2 * math.sqrt(mat.line_density / mat.alpha)
    chunk = max(1, int(round(t_bend / p.dt)))
    bend = []
    for _ in range(40):
        world.step(chunk)
        bend.append(out_of_plane(world.positions()))
        if bend[-1] > BUCKLED * radius:
            return True, world
    return max(bend[30:]) > 1.02 * max(bend[20:30]), world


def michell(p: CaseParams, tol: float = 0.002) -> list[dict]:
    """Critical twist of a naturally straight ring by bisection, against Michell's."""
    mat = p.material
    ref = reference.michell_critical_twist(mat.alpha, mat.beta)
    lo, hi = 0.5 * ref, 1.5 * ref
    t0 = time.perf_counter()
    stable, note, steps, world, trials = True, "", 0, None, 0
    samples = []  # the step times of every trial ring
    try:
        buckled_lo, world = ring_buckles(p, lo, samples=samples)
        steps += world.n_steps
        buckled_hi, world = ring_buckles(p, hi, samples=samples)
        steps += world.n_steps
        trials = 2
        if buckled_lo or not buckled_hi:
            raise RuntimeError(f"no threshold between {lo:.4g} and {hi:.4g} rad (buckled: {buckled_lo}, {buckled_hi})")
        while hi - lo > tol * ref:
            mid = 0.5 * (lo + hi)
            buckled, world = ring_buckles(p, mid, samples=samples)
            steps += world.n_steps
            trials += 1
            lo, hi = (lo, mid) if buckled else (mid, hi)
        measured = 0.5 * (lo + hi)
    except (DivergenceError, RuntimeError) as err:
        stable, note, measured = False, str(err), None
    wall = time.perf_counter() - t0
    rec = record("michell", p, world, measured, ref, stable, wall, beta_over_alpha=mat.beta / mat.alpha,
                 bracket=[lo, hi], trials=trials, note=note)
    rec["steps"], rec["sim_s"] = steps, steps * p.dt
    rec["us_per_step"] = median_step_us(samples)
    return [rec]


def circle(p: CaseParams, max_time: float = 300.0) -> list[dict]:
    """A clamped rod curled by the end couple 2 pi alpha / L into a closed circle."""
    mat = p.material
    moment = reference.closing_couple(mat.alpha, p.length)
    world = StepClock(p.build.cantilever(p, 0.0, 10.0)[0])
    t0 = time.perf_counter()
    stable, note, measured = True, "", None
    try:
        while world.time < max_time:
            for _ in range(50):
                # A couple on the last edge, following it as it turns (how depends on the backend).
                p.build.end_couple(world, moment)
                world.step()
            if np.max(np.abs(world.velocities())) < SETTLE_SPEED * p.length:
                break
        measured = float(np.linalg.norm(world.positions()[-1] - (0.0, 0.0, 1.0)) / p.length)
    except DivergenceError as err:
        stable, note = False, str(err)
    wall = time.perf_counter() - t0
    rec = record("circle", p, world, measured, 0.0, stable, wall, note=note)
    rec["rel_error"] = measured  # already relative to L
    return [rec]


def twister_world(p: CaseParams, servo: bool = True) -> World:
    """A rod clamped between the world (at x = 0) and a body on a hinge about x (at x = L)."""
    mat = p.material
    spec = mujoco.MjSpec()
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    turner = spec.worldbody.add_body(name="turner", pos=[p.length, 0.0, 1.0])
    turner.add_joint(name="turn", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1.0, 0.0, 0.0])
    # A disk, polar moment of inertia 0.5 m r^2 = 0.2 kg m^2 about the rod axis: heavy
    # enough that the stiff servo (kp h^2 / I = 1 at h = 1e-2) integrates stably.
    turner.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.2, 0.01, 0.0],
                    euler=[0.0, math.pi / 2, 0.0], mass=10.0, contype=0, conaffinity=0)
    if servo:
        act = spec.add_actuator(name="servo", target="turn", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=2000.0, kv=100.0)
    world = World(spec, dt=p.dt, gravity=(0.0, 0.0, 0.0), mode=p.mode, mass_damping=5.0)
    rod = Rod(shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0), clamped_ends=2), mat,
              boundary=TwistBoundary("clamped", 0.0, 0.0))
    world.add_rod(rod, "rod", start="clamp", end="clamp", end_body="turner")
    world.compile()
    return world


def twist(p: CaseParams, turns: float = 2.0, ramp: float = 2.0, hold: float = 3.0) -> list[dict]:
    """Reaction torque of a rod twisted by a servo-driven clamp (beta Theta / L)."""
    mat = p.material
    theta = 2 * math.pi * turns
    world = StepClock(twister_world(p))
    ref = None
    t0 = time.perf_counter()
    stable, note, measured = True, "", None
    try:
        n_ramp = int(round(ramp / p.dt))
        for k in range(n_ramp):
            world.data.ctrl[0] = theta * (k + 1) / n_ramp
            world.step()
        world.step(int(round(hold / p.dt)))
        measured = float(world.data.actuator_force[0])
        turned = float(world.data.qpos[world.model.joint("turn").qposadr[0]])
        ref = reference.twist_torque(mat.beta, turned, p.length)
        twist_in_rod = float(world.rod_state("rod").theta[-1] - world.rod_state("rod").theta[0])
    except DivergenceError as err:
        stable, note, twist_in_rod = False, str(err), None
    wall = time.perf_counter() - t0
    return [record("twist", p, world, measured, ref, stable, wall, turns=turns,
                   turned=turned if stable else None, twist_in_rod=twist_in_rod, note=note)]


def stability(p: CaseParams, steps: int = 300) -> list[dict]:
    """Is the cantilever stable at this E, n and dt? 300 steps from rest under gravity,
    no damping, with a 1e-6 m/s random start (symmetric rods hide their instabilities).
    Unstable: divergence reported (NaN, BADQACC, runaway speed), an edge stretched by
    more than 50 %, or the tip farther than 1.5 L from the clamp. measured: 1 stable, 0 not."""
    world, rest_x = p.build.cantilever(p, p.gravity, 0.0)
    world = StepClock(world)
    rng = np.random.default_rng(0)
    dofs = world.dofs()
    world.data.qvel[dofs] = rng.normal(scale=1e-6, size=len(dofs))
    t0 = time.perf_counter()
    stable, note = True, ""
    try:
        for _ in range(steps // 10):
            world.step(10)
            x = world.positions()
            if max_strain(x, rest_x) > 0.5 or np.linalg.norm(x[-1] - (0.0, 0.0, 1.0)) > 1.5 * p.length:
                raise DivergenceError(f"runaway shape at step {world.n_steps}")
    except DivergenceError as err:
        stable, note = False, str(err)
    wall = time.perf_counter() - t0
    rec = record("stability", p, world, 1.0 if stable else 0.0, 1.0, stable, wall, note=note)
    rec["rel_error"] = None
    rec["stable"] = stable
    return [rec]
