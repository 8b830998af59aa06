"""Worlds the physics tests build directly (not through the benchmark harness), and the
few measurements they share. Each helper says what it builds in SI units."""

from __future__ import annotations

import importlib.util
import math
import pathlib

import numpy as np

import derods
from derods import World, reference, shapes

#: A cantilever has settled when no vertex moves faster than this times its length [1/s].
SETTLE_SPEED = 1e-5


def first_mode_rate(mat: derods.Material, length: float, gravity: float = 9.81) -> float:
    """Angular frequency [rad/s] of a cantilever's slowest mode: bending, or the rod
    swinging as a pendulum, whichever is faster."""
    w1 = 2 * math.pi * reference.cantilever_frequency(mat.alpha, mat.line_density, length)
    return max(w1, math.sqrt(gravity / length) if gravity else 0.0)


def cantilever(mat: derods.Material, n: int, length: float = 1.0, dt: float = 1e-2, gravity: float = 9.81,
               mode: str = "implicit", mass_damping: float | None = None) -> World:
    """A rod clamped at (0, 0, 1) m along +x (the clamp at the middle of its first edge,
    :func:`derods.shapes.cantilever`). Damping defaults to 0.7 of critical on the slowest
    mode (mass damping 1.4 omega_1), which settles it fastest."""
    if mass_damping is None:
        mass_damping = 1.4 * first_mode_rate(mat, length, gravity)
    world = World(dt=dt, gravity=(0.0, 0.0, -gravity), mode=mode, mass_damping=mass_damping)
    world.add_rod(derods.Rod(shapes.cantilever(length, n, start=(0.0, 0.0, 1.0)), mat), "rod", start="clamp")
    return world


def settle(world: World, length: float, max_time: float = 30.0) -> bool:
    """Step in 0.1 s chunks until no vertex moves faster than SETTLE_SPEED * length;
    returns whether it settled within max_time [s]."""
    chunk = max(1, int(round(0.1 / world.model.opt.timestep)))
    while world.time < max_time:
        world.step(chunk)
        if np.max(np.abs(world.velocities())) < SETTLE_SPEED * length:
            return True
    return False


def tip_drop_error(mat: derods.Material, n: int, length: float = 1.0, **kwargs) -> float:
    """Relative error of a settled cantilever's tip drop against the inextensible elastica."""
    world = cantilever(mat, n, length, **kwargs)
    assert settle(world, length), "the cantilever did not settle"
    ref = reference.cantilever_elastica(mat.line_density * 9.81, length, mat.alpha)["tip_drop"]
    return (1.0 - world.positions()[-1, 2]) / ref - 1.0


def out_of_plane(x: np.ndarray) -> float:
    """Distance [m] of the vertices from their best-fit plane (rms)."""
    c = x - x.mean(axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / math.sqrt(len(x)))


def twisted_ring(mat: derods.Material, n: int, total_twist: float, circumference: float = 1.0,
                 dt: float = 1e-2, mode: str = "implicit") -> World:
    """A naturally straight ring with total twist [rad], no gravity, bent out of its plane
    by 1e-3 of its radius (modes 2 and 3)."""
    x = shapes.circle(circumference / (2 * math.pi), n)
    world = World(dt=dt, gravity=(0.0, 0.0, 0.0), mode=mode)
    world.add_rod(derods.Rod(x, mat, closed=True, natural_curvature=False,
                             boundary=derods.TwistBoundary("ring", total_twist=total_twist)), "ring")
    phi = 2 * math.pi * np.arange(n) / n
    xp = x.copy()
    xp[:, 2] += 1e-3 * circumference / (2 * math.pi) * (np.sin(2 * phi) + 0.1 * np.cos(3 * phi))
    world.set_positions("ring", xp)
    return world


def twister(mat: derods.Material, n: int = 20, length: float = 1.0, dt: float = 1e-2, servo: bool = True,
            mode: str = "implicit") -> World:
    """A rod clamped between the world (at x = 0) and a body "turner" on a hinge "turn"
    about x (at x = L), turned by a position servo (kp 2000 N m/rad, kv 100 N m s/rad).
    The body is a disk of polar moment of inertia 0.2 kg m^2: heavy enough that the stiff
    servo (kp h^2 / I = 1 at h = 1e-2) integrates stably."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    turner = spec.worldbody.add_body(name="turner", pos=[length, 0.0, 1.0])
    turner.add_joint(name="turn", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1.0, 0.0, 0.0])
    turner.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.2, 0.01, 0.0], euler=[0.0, math.pi / 2, 0.0],
                    mass=10.0, contype=0, conaffinity=0)
    if servo:
        act = spec.add_actuator(name="servo", target="turn", trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=2000.0, kv=100.0)
    world = World(spec, dt=dt, gravity=(0.0, 0.0, 0.0), mass_damping=5.0, mode=mode)
    rod = derods.Rod(shapes.cantilever(length, n, start=(0.0, 0.0, 1.0), clamped_ends=2), mat,
                     boundary=derods.TwistBoundary("clamped", 0.0, 0.0))
    world.add_rod(rod, "rod", start="clamp", end="clamp", end_body="turner")
    world.compile()
    return world


def buckles(world: World, mat: derods.Material, circumference: float = 1.0, dt: float = 1e-2) -> bool:
    """Whether a ring from :func:`twisted_ring` leaves its plane within 40 bending times
    R^2 sqrt(rho A / alpha): by more than 5 % of R, or still growing by more than 2 % from
    one window of 10 bending times to the next (near the threshold growth is slow)."""
    radius = circumference / (2 * math.pi)
    chunk = max(1, int(round(radius**2 * math.sqrt(mat.line_density / mat.alpha) / dt)))
    bend = []
    for _ in range(40):
        world.step(chunk)
        bend.append(out_of_plane(world.positions()))
        if bend[-1] > 0.05 * radius:
            return True
    return max(bend[30:]) > 1.02 * max(bend[20:30])


def example(name: str):
    """The script examples/<name>.py, imported as a module (its functions and constants)."""
    path = pathlib.Path(__file__).parents[1] / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_example", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
