"""Clamps and pins on MuJoCo bodies (derods/sim/clamps.py): the rod follows, the body feels it."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import rods

import derods
from derods import World, reference, shapes


def test_servo_twists_rod_and_feels_beta_theta_over_l():
    """Turning a clamp k = 2 times (ramped over 2 s, held 3 s) puts 4 pi of twist into the
    rod, and the servo holding it feels beta Theta / L with L the distance between the
    clamps (measured: equal to 1e-13; the servo lags its target by 0.026 %)."""
    mat = derods.Material(young=1e7)
    world = rods.twister(mat)
    for k in range(200):
        world.data.ctrl[0] = 4 * math.pi * (k + 1) / 200
        world.step()
    world.step(300)
    turned = float(world.data.qpos[world.model.joint("turn").qposadr[0]])
    state = world.rod_state("rod")
    assert turned == pytest.approx(4 * math.pi, rel=1e-3)
    assert state.theta[-1] - state.theta[0] == pytest.approx(turned, abs=1e-9)
    assert world.data.actuator_force[0] == pytest.approx(reference.twist_torque(mat.beta, turned, 1.0), rel=0.02)


def test_released_body_spins_back():
    """A body clamped to a twisted rod turns back when its servo lets go."""
    world = rods.twister(derods.Material(young=1e7))
    world.data.ctrl[0] = 2 * math.pi
    world.step(300)
    q = world.model.joint("turn").qposadr[0]
    twisted = float(world.data.qpos[q])
    assert twisted > 6.0
    world.model.actuator_gainprm[0, 0] = 0.0
    world.model.actuator_biasprm[0, :3] = 0.0
    world.step(100)
    dof = world.model.joint("turn").dofadr[0]
    assert world.data.qvel[dof] < -0.1
    assert world.data.qpos[q] < twisted - 0.1


def test_clamp_on_a_moving_body_carries_the_rod():
    """A clamp on a mocap body moved sideways: the held edge goes with it in the same step
    and the free end follows."""
    spec = mujoco.MjSpec()
    hand = spec.worldbody.add_body(name="hand", pos=[0.0, 0.0, 1.0], mocap=True)
    hand.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], contype=0, conaffinity=0)
    w = World(spec, dt=1e-2, gravity=(0, 0, 0), mass_damping=5.0)
    w.add_rod(derods.Rod(shapes.cantilever(0.5, 10, start=(0, 0, 1)), derods.Material(young=1e7)),
              "rod", start="clamp", start_body="hand")
    w.compile()
    for k in range(100):  # 0.2 m in 1 s
        w.data.mocap_pos[0] = [0.0, 0.002 * (k + 1), 1.0]
        w.step()
        np.testing.assert_allclose(w.positions("rod")[:2, 1], 0.002 * (k + 1), atol=1e-12)
    w.step(300)
    x = w.positions("rod")
    np.testing.assert_allclose(x[:2, 1], 0.2, atol=1e-9)
    np.testing.assert_allclose(x[-1], [0.5, 0.2, 1.0], atol=1e-3)


def test_body_clamp_errors():
    rod = derods.Rod(shapes.straight(1.0, 5), derods.Material(young=1e6))
    w = World()
    with pytest.raises(ValueError, match="is not a body of the scene"):
        w.add_rod(rod, start="clamp", start_body="nobody")
    with pytest.raises(ValueError, match="start_body='x' needs start='pin' or 'clamp'"):
        w.add_rod(rod, start_body="x")


@pytest.mark.parametrize("u0,weak", [((0, 0, 1), True), ((0, 1, 0), False)])
def test_anisotropic_cantilever_bends_with_the_stiffness_it_is_clamped_in(u0, weak):
    """A ribbon (semi-axes 10 and 4 mm) clamped flat sags with B1 = E I1 (weak), clamped on
    edge with B2 = E I2 (stiff); the Newton twist solve runs every step. Measured at n = 20,
    dt = 1e-2: -0.45 % and -0.25 % from the elastica of that stiffness."""
    from derods import reference

    mat = derods.Material(young=1e8, radius=0.01, radius2=0.004)
    b1, b2 = mat.bend_stiffness
    rod = derods.Rod(shapes.cantilever(1.0, 20, start=(0, 0, 1)), mat, u0=np.array(u0, float))
    assert rod.active_terms == ("stretch", "bend_material", "twist")
    w = World(dt=1e-2, mass_damping=8.0)
    w.add_rod(rod, start="clamp")
    w.step(600)
    drop = 1.0 - w.positions()[-1, 2]
    ref = reference.cantilever_elastica(mat.line_density * 9.81, 1.0, b1 if weak else b2)["tip_drop"]
    assert abs(drop / ref - 1) < 0.01
    assert np.abs(w.velocities()).max() < 1e-5


def test_naturally_curved_rod_keeps_its_shape():
    """A helix clamped at one end without gravity stays in its rest shape (no spurious force)."""
    x = shapes.helix(0.1, 0.05, 1.5, 30, start=(0, 0, 1))
    w = World(dt=1e-2, gravity=(0, 0, 0))
    w.add_rod(derods.Rod(x, derods.Material(young=1e7)), start="clamp")
    w.step(100)
    np.testing.assert_allclose(w.positions(), x, atol=1e-9)


@pytest.mark.parametrize("total", [1.0, 3.0, 5.0, 13.48])
def test_a_clamp_held_by_a_body_keeps_an_imposed_twist(total):
    """TwistBoundary("clamped", 0, Theta) with the far clamp on a body: the rod keeps
    Theta, not the nearest multiple of 2 pi (it snapped 1.0 -> 0, 5.0 -> 2 pi, 13.48 ->
    4 pi when the body carried the reference director instead of the material one).
    Tolerance 1e-9 rad: round-off of the unwrapped angle."""
    spec = mujoco.MjSpec()
    b = spec.worldbody.add_body(name="holder", pos=[1.0, 0.0, 1.0], mocap=True)
    b.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], contype=0, conaffinity=0)
    w = World(spec, dt=1e-2, gravity=(0, 0, 0), mass_damping=5.0)
    rod = derods.Rod(shapes.cantilever(1.0, 20, start=(0, 0, 1), clamped_ends=2), derods.Material(young=1e7),
                     boundary=derods.TwistBoundary("clamped", 0.0, total))
    w.add_rod(rod, "rod", start="clamp", end="clamp", end_body="holder")
    w.compile()
    w.step(50)
    state = w.rod_state("rod")
    assert state.theta[-1] - state.theta[0] == pytest.approx(total, abs=1e-9)


@pytest.mark.parametrize("mode", ["implicit", "alpha"])
def test_clamp_reaction_carries_the_settled_rods_weight(mode):
    """World.reaction: a settled cantilever pushes its clamp down with the weight of its
    free vertices and twists it with their moment about the clamp point (the middle of the
    clamped edge): the free vertices' balance, -grad = -m g at each, summed. Tolerance 1e-4
    of the load's size: what settling leaves (no vertex faster than 1e-5 m/s)."""
    mat = derods.Material(young=1e7)
    w = rods.cantilever(mat, 20, mode=mode)
    assert rods.settle(w, 1.0)
    w.step()
    x = w.positions("rod")
    free = np.arange(2, len(x))
    m = np.array([w.model.body_mass[w.vertex_body("rod", v)] for v in free])
    weight = m[:, None] * np.array([0.0, 0.0, -9.81])
    point = x[:2].mean(axis=0)
    force, moment = w.reaction("rod", "start")
    expected_force = weight.sum(axis=0)
    expected_moment = np.cross(x[free] - point, weight).sum(axis=0)
    np.testing.assert_allclose(force, expected_force, atol=1e-4 * np.linalg.norm(expected_force))
    np.testing.assert_allclose(moment, expected_moment, atol=1e-4 * np.linalg.norm(expected_moment))
    assert np.all(w.reaction("rod", "end")[0] == 0.0)  # a free end holds nothing
