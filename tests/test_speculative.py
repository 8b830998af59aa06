"""Speculative contacts: margins sized by each rod's speed (ContactParams(speculative=True),
derods/sim/speculative.py) and speculative pyramidal rows without friction
(derods/_numba/contact_reference.py). Each test states its tolerance and its source."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import derods
from derods import ContactParams, World, shapes
from derods.bench import held
from derods.validation import SceneWarning

R = 3e-3


def _floor_world(contact: ContactParams, dt: float, gravity=(0.0, 0.0, -9.81), mode: str = "implicit",
                 cone: str = "pyramidal") -> World:
    spec = mujoco.MjSpec()
    if cone == "elliptic":
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    floor = spec.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [5.0, 5.0, 0.1]
    return World(spec, dt=dt, gravity=gravity, contact=contact, mode=mode)


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_speculative_contact_carries_no_friction(cone):
    """A rod sliding at 1 m/s 0.1 mm above a floor, without gravity, inside a 3 mm contact
    margin: its contacts are speculative (rows before touching) and only keep it from
    crossing the surface, so it slides on unbraked and at its height (to 1e-6 over 0.1 s:
    round-off of 50 steps); on the floor itself it is braked (friction 0.5). With a
    pyramid's rows n +- mu t each kept from crossing, v_n h + d >= mu |v_t| h held the
    hovering rod back (its friction acting a hair above the floor); with an elliptic cone's
    frictional rows in play its middle zone pushed the rod off the floor, out of its margin
    (a force with no contact)."""
    def slide(height):
        world = _floor_world(ContactParams(friction=0.5, margin=3e-3), 2e-3, gravity=(0.0, 0.0, 0.0), cone=cone)
        world.add_rod(derods.Rod(shapes.straight(0.3, 30, start=(0.0, 0.0, R + height)),
                                 derods.Material(young=1e7, radius=R, density=1000.0)))
        world.compile()
        v = np.zeros_like(world.velocities())
        v[:, 0] = 1.0
        world.set_velocities(0, v)
        world.step()
        contacts = world.data.ncon
        world.step(49)
        return float(world.velocities()[:, 0].mean()), contacts, float(world.positions()[:, 2].mean()) - R

    hovering, contacts, height = slide(1e-4)
    assert contacts > 0  # speculative contacts, from the first step
    assert hovering == pytest.approx(1.0, abs=1e-6)
    assert height == pytest.approx(1e-4, abs=1e-6)  # not pushed off either
    touching, _, _ = slide(-1e-4)
    assert touching < 0.99


def _throw(speculative: bool, dt: float = 1e-2, gap: float = 0.02, speed: float = 4.0, steps: int = 60):
    """A 0.3 m rod (30 edges, E = 1e7) thrown flat at ``speed`` [m/s] down onto a floor from
    ``gap`` [m] above it; returns (the lowest vertex centre over the run [m], the rods'
    margin at the end [m], the world)."""
    world = _floor_world(ContactParams(speculative=speculative), dt)
    world.add_rod(derods.Rod(shapes.straight(0.3, 30, start=(0.0, 0.0, R + gap)),
                             derods.Material(young=1e7, radius=R, density=1000.0)))
    world.compile()
    v = np.zeros_like(world.velocities())
    v[:, 2] = -speed
    world.set_velocities(0, v)
    low = np.inf
    for _ in range(steps):
        world.step()
        low = min(low, float(world.positions()[:, 2].min()))
    return low, float(world.model.flex_margin[0]), world


def test_speed_margins_find_a_fast_rod_before_it_goes_in():
    """Thrown at 4 m/s from 2 cm above a floor at dt 1e-2 (4 cm a step): discrete detection
    finds it only inside, 2 cm deep (vertex centres 17 mm below the floor: more than r
    through it); with margins sized by speed (1.5 |v| h = 6 cm) its contacts exist from
    the first step and keep it out: the lowest centre within r / 2 of resting height r
    (r / 2: the sweep's resting criterion, derods/bench/held.py). At rest (0.6 s later) the
    margin is back to the static one, 0 (the rod travels no further in a step than a
    speculative row would let it sink, SpeedMargin.update)."""
    bare, _, _ = _throw(False)
    assert bare < -R  # the test can fail: without speculation the rod goes through
    caught, margin, world = _throw(True)
    assert caught > R / 2
    h = world.model.opt.timestep
    assert margin == 0.0


def test_speculative_contacts_leave_a_slow_landing_alone_within_its_resting_depth():
    """Dropped from 2 cm at 0.5 m/s (5 mm a step at dt 1e-2), both ways rest on the floor:
    the lowest vertex centre within r / 2 of resting height at the end (the sweep's
    resting criterion), the speculative rows change where, not whether, it lands."""
    for spec in (False, True):
        _, _, world = _throw(spec, speed=0.5)
        assert float(world.positions()[:, 2].min()) > R / 2


@pytest.mark.parametrize("case", [
    held.Case("drag", "mocap", mass=1.0, end="pin", dt=1e-2, young=1e10, n_edges=100),
    held.Case("edge", "mocap", mass=1.0, end="pin", dt=1e-2),
], ids=["stiff-cable-whipped-by-a-mocap-cart", "edge-mocap-pin"])
def test_the_held_sweeps_mocap_dips_at_a_large_step_are_gone_when_asked(case):
    """Two of the held sweep's mocap-cart cases that dip through their surface at dt 1e-2
    at defaults (a vertex centre more than r inside: 41 and 6.8 mm measured; discrete
    detection; rods held by the world or mocap bodies keep it by default, their records
    unchanged), with ContactParams(speculative=True): right by the sweep's own criterion (no
    centre more than r inside during the run, every one more than r / 2 out at its end, the
    tail following the cart). The whole sweep: benchmarks/bench_held.py --speculative."""
    assert not held.run(case)["ok"]  # at defaults: the test can fail
    r = held.run(held.Case(**{**case.__dict__, "speculative": True}))
    assert r["ok"], r["note"]


@pytest.mark.parametrize("case", [
    held.Case("drag", "slide", mass=0.1, end="pin", dt=1e-2),
    held.Case("edge", "slide", mass=1.0, end="clamp", dt=1e-2),
    held.Case("edge", "slide", mass=0.01, end="pin", dt=1e-2),
], ids=["drag-slide-0.1kg", "edge-slide-1kg-clamp", "edge-slide-10g-pin"])
def test_rods_held_by_bodies_with_dofs_are_speculative_by_default(case):
    """Rods held by bodies with dofs take speculative contacts by default
    (ContactParams(speculative=None)): three held-sweep cases at dt 1e-2 that dip through
    their surface without them (speculative=False: 5.1, 14 and 3.2 mm measured, limit r)
    are right at defaults."""
    assert not held.run(held.Case(**{**case.__dict__, "speculative": False}))["ok"]  # the test can fail
    r = held.run(case)
    assert r["ok"], r["note"]


def test_speculative_must_be_a_bool_and_needs_a_staged_mode():
    """A bad value names the parameter; the projection mode (mj_step's solver, which reads
    a margin as a skin) warns and leaves speculative contacts out."""
    with pytest.raises(ValueError, match="speculative"):
        ContactParams(speculative="yes")
    world = _floor_world(ContactParams(speculative=True), 1e-3, mode="projection")
    world.add_rod(derods.Rod(shapes.straight(0.3, 10, start=(0.0, 0.0, 0.1)),
                             derods.Material(young=1e7, radius=R, density=1000.0)))
    with pytest.warns(SceneWarning, match="speculative"):
        world.compile()
    assert world._step.speculative is None
