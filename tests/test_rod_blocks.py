"""The contact stage's one-pass blocks (derods._numba.rod_blocks: every row within one rod's
window) against the general stage (triplets, partition, per-block split), to the bit: the
acceleration, the forces on the rod dofs and MuJoCo's efc_force, after worlds of rods lying
on a floor, a rod across the box's edge, a clamped and twisted rod lying on the floor (twist
terms in the system), and rods heaped on each other (rod-rod rows: the general stage)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import derods._numba.contact as _k
from derods import ContactParams, Material, Rod, TwistBoundary, World, scenes, shapes
from derods._numba.rod_blocks import rods_own_rows
from derods.sim import contact as stage


def lying(count: int) -> World:
    """count rods of 32 vertices lying side by side on the floor."""
    world = World(scenes.path("floor"), dt=1e-2, mass_damping=2.0)
    for i in range(count):
        x = shapes.straight(0.31, 31, start=(0.0, 0.05 * i, 0.002))
        world.add_rod(Rod(x, Material(radius=2e-3, young=1e8), natural_curvature=False), f"r{i}")
    return world


def twisted_on_floor() -> World:
    """A rod clamped at both ends with a turn of twist, lying on the floor: its twist term
    in the implicit system, and a free rod beside it."""
    world = World(scenes.path("floor"), dt=1e-2, mass_damping=2.0)
    x = shapes.straight(0.4, 24, start=(0.0, 0.0, 0.004))
    world.add_rod(Rod(x, Material(radius=3e-3, young=1e7), boundary=TwistBoundary("clamped", 0.0, 2 * math.pi)),
                  "twisted", start="clamp", end="clamp")
    world.add_rod(Rod(shapes.straight(0.4, 24, start=(0.0, 0.05, 0.05)), Material(radius=3e-3, young=1e7)), "free")
    return world


def box_edge() -> World:
    world = World(scenes.path("box"), dt=1e-2, mass_damping=2.0)
    world.add_rod(Rod(shapes.straight(0.5, 30, start=(-0.1, 0.0, 0.45)), Material(young=1e7)), "rod")
    return world


def heap() -> World:
    """Three rods dropped crosswise onto each other on the floor: rod-rod rows."""
    world = World(scenes.path("floor"), dt=2e-3, contact=ContactParams(rod_rod=True))
    for i in range(3):
        x = shapes.straight(0.3, 20, start=(-0.15 * (i != 1), -0.15 * (i == 1), 0.02 + 0.012 * i),
                            direction=(1.0, 0.0, 0.0) if i != 1 else (0.0, 1.0, 0.0))
        world.add_rod(Rod(x, Material(radius=5e-3, young=1e6)), f"r{i}")
    return world


def stage_both_ways(world: World):
    """The contact stage of the world's current rows by contact_step and by the general
    stage's two halves, each on copies: (own rows?, results by contact_step, by the general
    stage)."""
    st, data = world._step, world.data
    c = st.contact
    efc, system = c.rows(data), st.system.arrays
    own = rods_own_rows(efc, stage.SUPPORTED, c.local_of_dof, c.dof_off, stage.WINDOW)[0]
    out = []
    for general in (False, True):
        e = efc._replace(force=efc.force.copy())
        a_out, f_out = np.full(len(st.a0), np.nan), np.full(len(st.a0), np.nan)
        args = (c.local_of_dof, c.dof_off)
        if general:
            blocks = _k.contact_blocks(e, stage.SUPPORTED, *args, system, st.a0, a_out, f_out)
            _k.solve_blocks(e, None, blocks, 0, blocks.n_blocks, *args, stage.WINDOW, system, st.a0, a_out, f_out,
                            stage.MAX_ITER, stage.TOL)
        else:
            _k.contact_step(e, None, stage.SUPPORTED, *args, stage.WINDOW, system, st.a0, a_out, f_out,
                            stage.MAX_ITER, stage.TOL)
        out.append((a_out, f_out, e.force[:data.nefc].copy()))
    return own, out[0], out[1]


@pytest.mark.parametrize("build, steps, expect_own", [
    (lambda: lying(3), 120, True),
    (lambda: lying(1), 120, True),
    (twisted_on_floor, 150, True),
    (box_edge, 150, True),
    (heap, 300, False),
], ids=["three lying rods", "one lying rod", "twisted rod on the floor", "box edge", "heap"])
def test_one_pass_blocks_give_the_general_stage_to_the_bit(build, steps, expect_own):
    world = build()
    seen, checked = 0, 0
    for k in range(steps):
        world.step()
        if k % 10 or not world.data.nefc:
            continue
        checked += 1
        own, fast, general = stage_both_ways(world)
        seen += own
        for x, y in zip(fast, general):
            assert np.array_equal(x, y)
    if expect_own:
        assert seen, "the one-pass blocks never ran: the test compares nothing"
    else:
        assert seen < checked, "rod-rod rows are not one rod's: the general stage must take some steps"


def test_rows_off_the_rods_or_too_wide_are_not_one_rods():
    """A row with an entry on a dof of no rod, or wider than the window, sends the step
    to the general stage."""
    world = lying(2)
    world.step(50)
    st, data = world._step, world.data
    c = st.contact
    efc = c.rows(data)
    assert rods_own_rows(efc, stage.SUPPORTED, c.local_of_dof, c.dof_off, stage.WINDOW)[0]
    assert not rods_own_rows(efc, stage.SUPPORTED, c.local_of_dof, c.dof_off, 2)[0]
    off = c.local_of_dof.copy()
    off[data.efc_J_colind[0]] = -1
    assert not rods_own_rows(efc, stage.SUPPORTED, off, c.dof_off, stage.WINDOW)[0]
    assert not rods_own_rows(efc, np.zeros(0, dtype=stage.SUPPORTED.dtype), c.local_of_dof, c.dof_off,
                             stage.WINDOW)[0]
