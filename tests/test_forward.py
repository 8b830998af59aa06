"""MuJoCo's forward pass without its constraint solver where derods solves every row
(derods/sim/forward.py): the same trajectories to the bit, the solver kept where a row is
not derods', and the stages equal to mj_forward where it does not skip."""

from __future__ import annotations

import mujoco
import numpy as np

import derods
from derods import World, scenes, shapes
from derods.sim.contact import SUPPORTED
from derods.sim.forward import Forward


def _dropped(scene: str, mode: str = "implicit", skip: bool = True, xml: str | None = None,
             steps: int = 150) -> tuple[World, int]:
    """A rod dropped onto ``scene`` (across the box scene's +x edge, 6 cm above its top; 8 cm
    above the floor) and stepped at dt 5e-3 (it lands and lies); returns the world
    and how many steps skipped MuJoCo's solver (``steps``: how many steps, 150)."""
    world = World(mujoco.MjSpec.from_string(xml) if xml else scenes.path(scene), dt=5e-3, mode=mode,
                  mass_damping=2.0)
    start = (0.0, 0.01, 0.26) if scene == "box" else (-0.2, 0.01, 0.08)
    world.add_rod(derods.Rod(shapes.straight(0.4, 20, start=start), derods.Material(young=1e7)), "rod")
    world.compile()
    forward = world._step.forward
    if not skip:
        forward.enabled = False
    skipped = 0
    for _ in range(steps):
        world.step()
        skipped += forward.skipped
    return world, skipped


def test_skipping_the_solver_changes_no_bit_of_the_trajectory():
    """A rod landing on the box scene's edge and lying there, implicit and alpha: MuJoCo's
    constraint solver skipped on most steps (every row is a rod's on static geometry) and
    the positions and velocities equal, to the bit, those of the same run with the solver
    run and its answer discarded."""
    for mode in ("implicit", "alpha"):
        fast, skipped = _dropped("box", mode)
        slow, none = _dropped("box", mode, skip=False)
        assert none == 0 and skipped > 50, (mode, skipped)
        assert np.array_equal(fast.data.qpos, slow.data.qpos), mode
        assert np.array_equal(fast.data.qvel, slow.data.qvel), mode


def test_the_solver_runs_where_a_row_is_not_the_rods():
    """A free box resting on the floor beside the rod: its own rows are MuJoCo's to solve,
    so no step skips, and the box stays on the floor (it would sink with no constraint
    force) while the rod lands beside it."""
    xml = """<mujoco><worldbody><geom name="floor" type="plane" size="2 2 0.1"/>
      <body name="box" pos="0 0.3 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.05" mass="1"/></body>
    </worldbody></mujoco>"""
    world, skipped = _dropped("", xml=xml)
    assert skipped == 0
    assert abs(world.data.body("box").xpos[2] - 0.05) < 1e-3
    assert world.positions("rod")[:, 2].min() > 0.0


def test_a_touch_sensor_reads_the_force_derods_applied():
    """A touch sensor on a pad the rod lands on and lies across reads, at every step, the
    normal force derods applied there (the pad's contacts' normal forces through
    mj_contactForce, which read derods' row forces), to 1e-9 of the rod's weight, with MuJoCo's
    solver skipped or run: the acceleration-stage sensors are computed again after derods'
    solve. (Before, computed inside MuJoCo's forward pass, they read MuJoCo's own answer.)"""
    xml = """<mujoco><worldbody><geom name="floor" type="plane" size="2 2 0.1"/>
      <body name="pad" pos="0 0.01 0.02"><geom name="pad" type="box" size="0.05 0.05 0.02"/>
        <site name="pad" type="box" size="0.06 0.06 0.03"/></body>
    </worldbody><sensor><touch name="touch" site="pad"/></sensor></mujoco>"""
    for skip in (True, False):
        world, skipped = _dropped("", xml=xml, skip=skip, steps=0)
        m, d = world.model, world.data
        pad = m.geom("pad").id
        weight = derods.Material(young=1e7).line_density * 0.4 * 9.81
        f6, checked = np.zeros(6), 0
        for _ in range(150):
            world.step()
            skipped += world._step.forward.skipped
            normal = 0.0
            for i in range(d.ncon):
                if pad in d.contact[i].geom:
                    mujoco.mj_contactForce(m, d, i, f6)
                    normal += f6[0]
            if normal > 0.0:
                assert abs(d.sensor("touch").data[0] - normal) < 1e-9 * weight
                checked += 1
        assert checked > 50 and (skipped > 50) == skip, (checked, skipped)


def test_the_stages_are_mj_forward_where_nothing_is_skipped():
    """Forward's stages (the position stage, then mj_forwardSkip) leave every array of
    MuJoCo's data as mj_forward does, on a model with contacts, a joint limit, an
    actuator, position and velocity sensors and energy (efc_J's sparse index arrays are
    left out: unused by a dense model and not rewritten)."""
    xml = """<mujoco><option><flag energy="enable"/></option><worldbody><geom type="plane" size="2 2 .1"/>
      <body pos="0 0 .04"><freejoint/><geom type="box" size=".05 .05 .05"/><site name="s"/></body>
      <body pos=".3 0 .3"><joint name="h" type="hinge" axis="0 1 0" range="-1 1" limited="true"/>
        <geom type="capsule" fromto="0 0 0 .2 0 0" size=".02"/></body>
    </worldbody><actuator><motor joint="h"/></actuator>
    <sensor><framepos objtype="site" objname="s"/><jointvel joint="h"/></sensor></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)

    def fresh():
        d = mujoco.MjData(m)
        d.qvel[:] = np.linspace(-0.5, 0.5, m.nv)
        d.ctrl[:] = 0.3
        mujoco.mj_step(m, d)
        return d

    plain, staged = fresh(), fresh()
    mujoco.mj_forward(m, plain)
    forward = Forward(m, np.zeros(m.nv, dtype=bool), SUPPORTED)
    forward(staged)
    assert plain.nefc > 0 and not forward.skipped
    skip = {"timer", "solver", "warning", "time", "efc_J_colind", "efc_J_rowadr", "efc_J_rownnz", "efc_J_rowsuper"}
    for name in dir(plain):
        a = getattr(plain, name)
        if name.startswith("_") or name in skip or not isinstance(a, np.ndarray) or a.dtype == object:
            continue
        assert np.array_equal(a, getattr(staged, name), equal_nan=True), name


def _mujoco_contact_total(world: World) -> np.ndarray:
    """The total force [N] (3,) of every contact as mj_contactForce reads it, in the world frame."""
    m, d = world.model, world.data
    f6, total = np.zeros(6), np.zeros(3)
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, f6)
        total += d.contact[i].frame.reshape(3, 3).T @ f6[:3]
    return total


def test_mujocos_readers_see_the_contact_forces_derods_applied():
    """mj_contactForce (and so the viewer and a user's grasp monitor) reads efc_force: derods
    writes its own row forces there, with MuJoCo's solver skipped or run. A rod landing on
    the box's edge, sliding and coming to rest: at every contact step the contacts' total
    force equals the force derods applied to the rod (World.contact_force), to round-off
    (1e-9 of the rod's weight); before, with the solver run, it was MuJoCo's own answer
    (and with it skipped, 0)."""
    for skip in (True, False):
        world = World(scenes.path("box"), dt=5e-3, mass_damping=2.0)
        mat = derods.Material(young=1e7)
        world.add_rod(derods.Rod(shapes.straight(0.4, 20, start=(0.0, 0.01, 0.26)), mat), "rod")
        world.compile()
        if not skip:
            world._step.forward.enabled = False
        weight = mat.line_density * 0.4 * 9.81
        checked = 0
        for _ in range(150):
            world.step()
            if world.data.ncon:
                applied = world.contact_force().sum(axis=0)
                np.testing.assert_allclose(_mujoco_contact_total(world), applied, rtol=0, atol=1e-9 * weight)
                checked += 1
        assert checked > 50, checked
