"""Rods held by bodies with dofs, solved together with them (derods/sim/holders.py)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from derods import bench, reference
from derods.bench import coupling
from derods.sim import holder_stiffness, holders, trees


@pytest.mark.parametrize("scene", coupling.SCENES)
@pytest.mark.parametrize("young", [1e5, 1e10])
@pytest.mark.parametrize("mass", [1e-3, 1e4])
def test_a_clamp_on_a_body_of_any_mass_is_stable_at_a_large_step(scene, young, mass):
    """Issue 14's scenes: a 0.31 kg rod clamped to a 1 g .. 10 t body on a slide along the rod,
    a free joint or a hinged arm, moved 1e-6 m: over 300 steps at dt = 1e-2 nothing diverges and the
    energy (elastic + kinetic) never rises 1 % above its start (nothing feeds the motion;
    an unstable mode grows it by orders of magnitude)."""
    p = bench.CaseParams(n_edges=20, dt=1e-2, young=young)
    r = coupling.perturbed(p, scene, mass)
    assert r["stable"], r["note"]


def test_the_same_clamp_applied_one_step_late_diverges(monkeypatch):
    """The scene can fail: without the coupled solve (the reaction applied explicitly, as
    before) a 1 kg body on the slide diverges within a few steps."""
    monkeypatch.setattr(holders.Holders, "__bool__", lambda self: False)
    p = bench.CaseParams(n_edges=20, dt=1e-2, young=1e7)
    assert not coupling.perturbed(p, "slide", 1.0)["stable"]


def test_mujoco_velocity_derivative_is_its_damping_and_servo_gain():
    """smooth_vel reaches MuJoCo's own mjd_smooth_vel: joint damping and a position servo's
    kv appear in qDeriv as -damping and -kv (exact)."""
    xml = """<mujoco><option integrator="implicitfast"/><worldbody>
      <body><joint type="hinge" damping="0.3"/><geom size=".1" pos=".2 0 0"/>
        <body pos=".4 0 0"><joint name="k" type="slide" axis="1 0 0"/><geom size=".1"/></body></body>
    </worldbody><actuator><position joint="k" kp="10" kv="2"/></actuator></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    trees.smooth_vel(m, d, False)
    diag = [d.qDeriv[m.D_rowadr[i] + list(m.D_colind[m.D_rowadr[i]:m.D_rowadr[i] + m.D_rownnz[i]]).index(i)]
            for i in range(m.nv)]
    np.testing.assert_array_equal(diag, [-0.3, -2.0])


def test_a_damped_holder_moves_as_mujoco_integrates_it():
    """A free body with linear joint damping c pinned to the tip: the coupled rows give
    MuJoCo's implicit integrator (M - h D) qacc = f back exactly, so the body's
    acceleration is the coupled solve's (no double-counted damping): qacc stays finite
    and the pair swings at the closed form's frequency within 1 %."""
    p = bench.CaseParams(n_edges=20, dt=1e-2, young=1e7)
    rod_mass = p.material.line_density * p.length
    world = coupling.held_world(p, rod_mass, joint_damping=1e-3)
    assert world._step.holders
    rest = world.positions("rod").copy()
    coupling._bend(world, rest, p.length)
    ref = reference.tip_mass_frequency(p.material.alpha, p.material.line_density, p.length, 1.0)
    n = int(3.25 / ref / p.dt)
    z = np.empty(n)
    for k in range(n):
        world.step()
        z[k] = world.positions("rod")[-1, 2] - 1.0
    from derods.bench.measures import crossing_frequency

    assert crossing_frequency(z, p.dt) == pytest.approx(ref, rel=1e-2)


def test_a_free_rod_pinned_to_a_free_body_keeps_its_linear_momentum():
    """No gravity, a bent free rod with random vertex velocities pinned to a free body of
    1 mg to 300 kg: the total linear momentum (MuJoCo's, every body) stays within 1e-9 of
    its start over 200 steps (issue 14's target; measured 2e-10, a free rod alone 2e-10:
    round-off of a stiff K). The coupling blocks are the band's own Gauss-Newton blocks,
    the held points' Jacobian MuJoCo's exact one."""
    from derods import shapes
    from derods.rod import Rod
    from derods.sim.world import World

    p = bench.CaseParams(n_edges=20, dt=1e-2, young=1e7)
    x = shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    x[:, 2] += 0.1 * np.sin(np.pi * x[:, 0])
    for mass in (1e-6, 0.3, 300.0):
        spec = mujoco.MjSpec()
        body = spec.worldbody.add_body(name="holder", pos=x[-1])
        body.add_freejoint()
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], mass=mass, contype=0, conaffinity=0)
        world = World(spec, dt=p.dt, gravity=(0.0, 0.0, 0.0))
        world.add_rod(Rod(x, p.material), "rod", end="pin", end_body="holder")
        world.compile()
        world.set_velocities("rod", np.random.default_rng(0).normal(size=x.shape) * 0.1)
        m, d = world.model, world.data

        def momentum():
            mujoco.mj_forward(m, d)
            mujoco.mj_subtreeVel(m, d)
            return m.body_subtreemass[0] * d.subtree_linvel[0]

        p0 = momentum()
        drift = 0.0
        for _ in range(200):
            world.step()
            drift = max(drift, np.linalg.norm(momentum() - p0) / np.linalg.norm(p0))
        assert drift < 1e-9, (mass, drift)


def test_rotational_dofs_are_told_from_translations():
    """Hinges, balls and a free joint's last three dofs turn their body; slides and a free
    joint's first three do not (numpy's int32 joint type is never `in` a tuple of MuJoCo's
    enums: every hinge was taken for a translation, and a clamp on a hinged body lost its
    frame-turning column)."""
    xml = """<mujoco><worldbody>
      <body><joint type="hinge"/><geom size=".1"/></body>
      <body pos="1 0 0"><joint type="ball"/><geom size=".1"/></body>
      <body pos="2 0 0"><joint type="slide"/><geom size=".1"/></body>
      <body pos="3 0 0"><freejoint/><geom size=".1"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    assert [holder_stiffness.rotational(m, i) for i in range(m.nv)] == [True] * 4 + [False] + [False] * 3 + [True] * 3
