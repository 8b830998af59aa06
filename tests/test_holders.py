"""Rods held by bodies with dofs, solved together with them (derods/sim/holders.py)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from derods import bench
from derods.bench import coupling
from derods.sim import holders


@pytest.mark.parametrize("scene", coupling.SCENES)
@pytest.mark.parametrize("young", [1e5, 1e10])
@pytest.mark.parametrize("mass", [1e-3, 1e4])
def test_a_clamp_on_a_body_of_any_mass_is_stable_at_a_large_step(scene, young, mass):
    """Issue 14's scenes: a 0.31 kg rod clamped to a 1 g .. 10 t body on a slide along the rod
    or a free joint, moved 1e-6 m: the displacement never exceeds 10 times that (bound
    from energy: nothing feeds the motion; the step damps it) at dt = 1e-2."""
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
    holders.smooth_vel(m, d, False)
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
    ref = coupling.tip_mass_frequency(p.material.alpha, p.material.line_density, p.length, 1.0)
    n = int(3.25 / ref / p.dt)
    z = np.empty(n)
    for k in range(n):
        world.step()
        z[k] = world.positions("rod")[-1, 2] - 1.0
    from derods.bench.cases import crossing_frequency

    assert crossing_frequency(z, p.dt) == pytest.approx(ref, rel=1e-2)
