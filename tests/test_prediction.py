"""The implicit step's prediction and conclusion as one compiled call each
(derods/_numba/implicit_stages.py, Implicit._predict and _conclude) against the same
kernels called one by one (Implicit.step's staged path): the same trajectory to the bit
wherever a world takes them, the same failures, and the worlds that must not take them do
not."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

import derods
from derods import TwistBoundary, scenes, shapes
from derods._numba import parallel


def _staged(world: derods.World) -> derods.World:
    """world stepping its prediction kernel by kernel, as before the one call."""
    world.compile()
    world._step._in_one_call = lambda: False
    return world


def _cantilever() -> derods.World:
    w = derods.World(dt=1e-2, mass_damping=2.0)
    w.add_rod(derods.Rod(shapes.cantilever(0.5, 20, start=(0, 0, 1)), derods.Material(young=1e7)), "r", start="clamp")
    return w


def _twisted() -> derods.World:
    """Both ends clamped, a turn of twist at the end: the twist term in A (Sherman-Morrison)."""
    w = derods.World(dt=1e-2, mass_damping=2.0)
    rod = derods.Rod(shapes.cantilever(0.4, 16, start=(0, 0, 1)), derods.Material(young=1e7),
                     boundary=TwistBoundary("clamped", 0.0, 2 * math.pi))
    w.add_rod(rod, "r", start="clamp", end="clamp")
    return w


def _dropped(scene: str, strain_limit: float | None = None) -> derods.World:
    """A rod dropped onto the box's edge or the floor (contact, the strain limit projecting
    turning edges); strain_limit: World's (None: the default)."""
    kw = {} if strain_limit is None else {"strain_limit": strain_limit}
    w = derods.World(scenes.path(scene), dt=1e-2, mass_damping=2.0, **kw)
    x = shapes.straight(0.5, 30, start=(-0.1, 0.0, 0.45))
    w.add_rod(derods.Rod(x, derods.Material(young=1e7)), "r")
    return w


def _curved() -> derods.World:
    """A naturally curved, anisotropic rod (the material-frame kernel and its twist solve)."""
    w = derods.World(scenes.path("floor"), dt=1e-2, mass_damping=2.0)
    x = shapes.helix(0.05, 0.02, 2.0, 40) + np.array([0.0, 0.0, 0.2])
    mat = derods.Material(young=1e7, radius=0.004, radius2=0.002)
    w.add_rod(derods.Rod(x, mat), "r")
    return w


def _ring() -> derods.World:
    w = derods.World(scenes.path("floor"), dt=1e-2, mass_damping=2.0)
    w.add_rod(derods.Rod(shapes.circle(0.1, 24) + np.array([0.0, 0.0, 0.2]), derods.Material(young=1e7),
                         closed=True, boundary=TwistBoundary("ring", total_twist=0.0)), "ring")
    return w


@pytest.mark.parametrize("build", [_cantilever, _twisted, lambda: _dropped("box"), lambda: _dropped("floor"),
                                   lambda: _dropped("floor", math.inf), _curved, _ring],
                         ids=["cantilever", "twisted", "box edge", "floor", "no strain limit", "curved", "ring"])
def test_one_call_steps_the_same_trajectory_to_the_bit(build):
    """150 steps (falling, landing, lying; the strain limit projecting) of each world, once
    by the one call and once kernel by kernel: positions, velocities and the rods' twist
    angles equal to the bit."""
    one, staged = build(), _staged(build())
    one.compile()
    assert one._step._in_one_call()
    for _ in range(150):
        one.step()
        staged.step()
    for a, b in ((one.data.qpos, staged.data.qpos), (one.data.qvel, staged.data.qvel),
                 (one._step.frames.theta, staged._step.frames.theta)):
        assert np.array_equal(a, b)
    assert one._step.n_projected == staged._step.n_projected


def test_a_rod_strained_beyond_the_limit_is_stopped_the_same_way():
    """An edge stretched to 2.2 times its length (the state set so) stops the step with the
    staged path's diagnosis, and the world is put back to the same state."""
    errors, states = [], []
    for world in (_cantilever(), _staged(_cantilever())):
        world.step(3)
        x = world.positions("r").copy()
        x[5:] += [0.0, 0.0, -0.05]  # edge 4 to 5: 5.6 cm long where it was 2.5
        world.set_positions("r", x)
        with pytest.raises(derods.DivergenceError, match="edge strain 1.2. exceeds") as err:
            world.step()
        errors.append(str(err.value))
        states.append(world.data.qpos.copy())
    assert errors[0] == errors[1]
    assert np.array_equal(states[0], states[1])


def test_a_system_not_positive_definite_is_reported_by_the_one_call():
    """A negative mass makes A indefinite: the one call's ValueError becomes the step's
    diagnosis, as the staged solve's does."""
    world = _cantilever()
    world.compile()
    world._step.system.arrays.mass[-3:] = -1.0
    with pytest.raises(derods.DivergenceError, match="not positive definite"):
        world.step()


def _held(mocap: bool) -> derods.World:
    """A rod pinned to a hand: a mocap body (moved by the user: prescribed vertices) or a
    1 kg cart on a slide (a holder with dofs, solved with the rod)."""
    spec = mujoco.MjSpec()
    hand = spec.worldbody.add_body(name="hand", pos=[0.0, 0.0, 1.0], mocap=mocap)
    if not mocap:
        hand.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1.0, 0.0, 0.0])
    hand.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], mass=1.0, contype=0, conaffinity=0)
    w = derods.World(spec, dt=1e-2)
    w.add_rod(derods.Rod(shapes.straight(0.3, 20, start=(0, 0, 1), direction=(-1, 0, 0)), derods.Material(young=1e7)),
              "r", start="pin", start_body="hand")
    w.compile()
    return w


def test_worlds_that_need_python_between_the_kernels_step_them_one_by_one():
    """A rod held by a mocap body, a rod pinned to a body with dofs, rods on threads and the
    alpha mode do not predict in one call (each needs Python between the kernels); the
    plain world does."""
    plain = _cantilever()
    plain.compile()
    assert plain._step._in_one_call()
    assert not _held(mocap=True)._step._in_one_call()
    assert not _held(mocap=False)._step._in_one_call()
    threaded = _cantilever()
    threaded.compile()
    st = threaded._step
    st.use_split(parallel.split(np.array([0, 10, 21]), np.array([0, 27, 60]), st.rod_tw, 2))
    assert st.split.parallel and not st._in_one_call()
    alpha = derods.World(dt=1e-2, mode="alpha")
    alpha.add_rod(derods.Rod(shapes.cantilever(0.5, 20, start=(0, 0, 1)), derods.Material(young=1e7)), "r",
                  start="clamp")
    alpha.compile()
    assert not alpha._step._in_one_call()
