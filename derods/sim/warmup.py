"""Compile every kernel of the step before a simulation starts.

numba compiles a kernel on its first call and caches the machine code on disk
(``__pycache__`` next to the source); a first run compiles everything (tens of
seconds of CPU), later runs load the cache in about a second. :func:`warm_up`
makes each kernel's first call happen up front, on small worlds that exercise
every path of the step (isotropic, anisotropic and curved rods, a twisted ring,
clamps on a moving body, contact with an obstacle and with the rod itself, elliptic
friction cones, explicit and projection modes), so no simulation stalls in the middle when a
path is first taken (the first contact, say). :func:`prepare` says so when it
takes long.
"""

from __future__ import annotations

import sys
import threading
import time

#: Seconds of silence after which :func:`prepare` says that kernels are being compiled. A
#: warm-up from the cache takes 0.8-1.1 s on a 2-core VM (imports and loading the cached
#: machine code), a first compile about a minute: at 1 s the notice also came, falsely, on
#: cached runs of a loaded machine.
NOTICE_AFTER = 3.0


def warm_up() -> None:
    """Run one short world of every kind, so every kernel is compiled (or loaded)."""
    import mujoco
    import numpy as np

    from .. import shapes
    from ..material import Material
    from ..rod import Rod
    from ..twist import TwistBoundary
    from .world import ContactParams, World

    mat = Material(young=1e7, radius=0.01)
    # Contact with an obstacle, a self-touching ring, a clamp on a moving body, a curved
    # and an anisotropic rod, and a twisted isotropic one: one world, a few steps.
    spec = mujoco.MjSpec()
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.1])
    hand = spec.worldbody.add_body(name="warmup_hand", pos=[0.0, 1.0, 0.5], mocap=True)
    hand.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], contype=0, conaffinity=0)
    world = World(spec, dt=1e-2, mass_damping=1.0, contact=ContactParams(self_collision=True))
    world.add_rod(Rod(shapes.straight(0.5, 8, start=(-0.25, 0.0, 0.011)), mat), "lying")
    world.add_rod(Rod(shapes.circle(0.05, 12, center=(0.0, -0.5, 0.011)), mat, closed=True,
                      natural_curvature=False, boundary=TwistBoundary("ring", total_twist=2.0)), "ring")
    world.add_rod(Rod(shapes.cantilever(0.3, 6, start=(0.0, 1.0, 0.5)), mat,
                      boundary=TwistBoundary("clamped", 0.0, 1.0)), "held", start="clamp", end="clamp",
                  start_body="warmup_hand")
    world.add_rod(Rod(shapes.helix(0.03, 0.02, 1.0, 8, start=(0.5, 0.5, 0.3)), mat), "curl", start="clamp")
    world.add_rod(Rod(shapes.straight(0.3, 6, start=(-0.5, 0.5, 0.3)), Material(young=1e7, radius=0.01,
                                                                                 radius2=0.005)), "ribbon")
    world.step(3)
    world.contact_force("lying")
    # The contact stage in its two halves, as worlds of many touching rods run it on two
    # threads (derods.sim.contact.SPLIT_MIN_ROWS): compiled here, not at such a world's
    # first step (~15 s).
    world._step.contact._threaded, world._step.contact.split_min_rows = True, 0
    world.step(2)
    # Rods held by bodies with dofs (derods.sim.coupled): a slide cart holding a rod that
    # lies on the floor (the bordered contact solve) and a hinged arm (arcs, differences).
    floor = '<geom type="plane" size="2 2 0.1"/>'
    cart = ('<body name="warmup_cart" pos="0 0 0.012"><joint type="slide" axis="1 0 0"/>'
            '<geom type="box" size="0.01 0.01 0.01" contype="0" conaffinity="0"/></body>')
    dragged = shapes.straight(0.3, 6, start=(0.0, 0.0, 0.0099), direction=(-1.0, 0.0, 0.0))
    spec = mujoco.MjSpec.from_string(
        f'<mujoco><worldbody>{floor}{cart}'
        '<body name="warmup_arm" pos="0 1 0.5"><joint type="hinge" axis="0 1 0" pos="0 0 0.1"/>'
        '<geom type="sphere" size="0.01" contype="0" conaffinity="0"/></body></worldbody></mujoco>')
    # (with speculative contacts: the reference correction and its pyramids made normal rows)
    held = World(spec, dt=1e-2, contact=ContactParams(speculative=True))
    held.add_rod(Rod(dragged, mat), "dragged", start="pin", start_body="warmup_cart")
    held.add_rod(Rod(shapes.straight(0.3, 6, start=(0.0, 1.0, 0.5), direction=(0.0, 0.0, -1.0)), mat), "hanging",
                 start="clamp", start_body="warmup_arm")
    held.step(3)
    # The strain limit's last resort for held rods (derods.sim.held_limit), which only a
    # rod out of its holders' reach reaches: a 2-edge rod, its end held by a point of 1 kg.
    from .._numba.held_projection import HeldPoints, limit_held
    x = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.25, 0.0, 0.0]])
    limit_held(x, np.array([0, 3]), np.array([0, 2]), np.full(2, 0.1), np.array([0.0, 1.0, 0.0]),
               np.array([-1, 0, -1]), np.zeros(3), np.zeros(3), 1e-2, np.array([0]), 1e-3, 1e-10, 5,
               np.zeros_like(x), x, HeldPoints(np.array([-1, -1, 0]), np.eye(3), np.zeros(3)))
    # Elliptic friction cones (derods._numba.cones), anchored (static friction), in a rod's
    # own block and in the border of a rod held by a body with dofs.
    spec = mujoco.MjSpec.from_string(f'<mujoco><option cone="elliptic"/><worldbody>{floor}{cart}</worldbody></mujoco>')
    cones = World(spec, dt=1e-2, contact=ContactParams(static_friction=True))
    cones.add_rod(Rod(dragged, mat), "dragged", start="pin", start_body="warmup_cart")
    cones.step(3)
    # (Two rods held by nothing: their step runs its stages in one call each,
    # derods._numba.implicit_stages.)
    for friction in (False, True):
        spec = mujoco.MjSpec.from_string(f'<mujoco><option cone="elliptic"/><worldbody>{floor}</worldbody></mujoco>')
        cones = World(spec, dt=1e-2, contact=ContactParams(static_friction=friction))
        cones.add_rod(Rod(shapes.straight(0.3, 6, start=(0.0, 0.5, 0.0099)), mat), "lying")
        cones.add_rod(Rod(shapes.straight(0.3, 6, start=(0.0, 0.7, 0.0099)), mat), "beside")
        cones.step(2)
        cones._step.contact._threaded, cones._step.contact.split_min_rows = True, 0  # (as above)
        cones.step(1)
    for mode in ("explicit", "projection"):
        w = World(dt=1e-5 if mode == "explicit" else 1e-2, mode=mode)
        w.add_rod(Rod(shapes.cantilever(0.3, 6), mat), start="clamp")
        w.step(2)
    # The public one-rod path and a batch of rods.
    for rod in (Rod(shapes.straight(0.3, 6), mat),
                Rod(np.stack([shapes.straight(0.3, 6)] * 2), mat)):
        rod.step_terms(rod.rest_state(), rod.rest_x)


def prepare(stream=None) -> float:
    """:func:`warm_up`, saying on ``stream`` (stderr) what is happening if it takes longer
    than :data:`NOTICE_AFTER` seconds (a first run compiles); returns the seconds it took."""
    stream = sys.stderr if stream is None else stream
    done = threading.Event()

    def notice():
        if not done.wait(NOTICE_AFTER):
            print("compiling derods' kernels (first run only; about a minute of CPU, cached for later runs)...",
                  file=stream, flush=True)

    t0 = time.perf_counter()
    timer = threading.Thread(target=notice, daemon=True)
    timer.start()
    try:
        warm_up()
    finally:
        done.set()
        timer.join()
    return time.perf_counter() - t0
