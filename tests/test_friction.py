"""Static friction: a rod resting on an incline below its friction angle stays put, and
slides at Coulomb's rate above it.

Coulomb: a body on a plane tilted by theta holds while tan(theta) < mu, without
creeping, and slides with acceleration g (sin theta - mu cos theta) beyond. cosseratbench's
capstan asks the same of a heavy rope over a cylinder (below the holding overhang it must
move < 1 mm in 2 s); this is the smallest case that shows it.

Without anchors (``ContactParams(static_friction=False)``: MuJoCo's soft friction alone,
re-solved in the implicit metric) the rope creeps: 7.4 mm/s on a 10 degree incline at mu =
0.3 (E = 3e5 Pa), 1.4 mm/s at E = 1e9. Two causes, measured: inside the friction cone both
rows of a pyramid pair are active and their friction is a damper, f_t = 2 mu^2 D (-B v_t -
a_t), with no tangential position term, so a loaded contact slides at a steady speed; and
the pair across the slope (its rows see the same penetration) carries two fifths of the
normal force, so friction along the slope topped out at tan(10 deg) of it against mu =
0.3. derods.sim.friction (``ContactParams(static_friction=True)``) anchors each resting
contact where it began and
gives its rows the slip since (MuJoCo's own stiffness K imp along the tangents): measured
0.0012 mm/s at E = 3e5 and 0 at 1e9 on 10 degrees, 0.0028 and 0 on 15 degrees (0.89 of
the friction angle); at 20 and 25 degrees it slides within 0.5 % of Coulomb's
acceleration.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

import derods
from derods import ContactParams, World, shapes

#: The capstan's criterion, per second: static friction lets a held rope move < 1 mm in 2 s.
CREEP_LIMIT = 0.5e-3  # m/s


def _rope_on_incline(young: float, tilt_deg: float = 10.0, friction: float = 0.3, dt: float = 1e-3,
                     mode: str = "implicit", static_friction: bool = False, cone: str = "pyramidal") -> World:
    """A 0.2 m rope (r = 1 mm, 20 edges) lying along the slope of a plane tilted by tilt_deg,
    its contacts' friction cones MuJoCo's ``cone`` ("pyramidal" or "elliptic")."""
    tilt = math.radians(tilt_deg)
    normal = np.array([-math.sin(tilt), 0.0, math.cos(tilt)])
    along = np.array([math.cos(tilt), 0.0, math.sin(tilt)])
    spec = mujoco.MjSpec()
    spec.option.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    plane = spec.worldbody.add_geom()
    plane.type = mujoco.mjtGeom.mjGEOM_PLANE
    plane.size = [0.0, 0.0, 1.0]
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, normal)
    plane.quat = quat
    plane.friction = [friction, 0.0, 0.0]
    radius = 1e-3
    world = World(spec, dt=dt, gravity=(0.0, 0.0, -9.81), mode=mode,
                  contact=ContactParams(friction=friction, static_friction=static_friction))
    material = derods.Material(young=young, radius=radius, density=1000.0)
    world.add_rod(derods.Rod(shapes.straight(0.2, 20, start=normal * radius, direction=along), material,
                             stretch_stiffness=material.stretch_stiffness))
    return world


#: Coulomb's sliding acceleration, relative: measured within 0.5 % (a sliding contact is
#: anchored again every step, so the anchors leave kinetic friction as it was).
SLIDE_TOL = 0.01


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("mode", ["implicit", "alpha"])
@pytest.mark.parametrize("tilt", [10.0, 15.0])
@pytest.mark.parametrize("young", [3e5, 1e9])
def test_a_rope_on_an_incline_below_its_friction_angle_holds(young, tilt, mode, cone):
    """tan(10 deg) = 0.18 and tan(15 deg) = 0.27 < mu = 0.3, static friction on: after
    settling for 0.2 s, the rope's centre moves less than CREEP_LIMIT along the slope over
    the next 0.5 s, with pyramidal or elliptic cones."""
    world = _rope_on_incline(young, tilt_deg=tilt, mode=mode, static_friction=True, cone=cone)
    world.step(200)
    before = world.positions().mean(axis=0)
    world.step(500)
    creep = np.linalg.norm(world.positions().mean(axis=0) - before) / 0.5
    assert creep < CREEP_LIMIT, f"creeps at {creep * 1e3:.2f} mm/s"


def test_without_anchors_the_rope_creeps():
    """The same rope (E = 3e5 Pa, 10 degrees) with ``static_friction=False``, the default:
    MuJoCo's soft friction, a damper inside the cone, lets it creep 7.4 mm/s (measured): the
    anchors are what holds it."""
    world = _rope_on_incline(3e5)
    world.step(200)
    before = world.positions().mean(axis=0)
    world.step(500)
    creep = np.linalg.norm(world.positions().mean(axis=0) - before) / 0.5
    assert creep > 10 * CREEP_LIMIT, f"creeps at {creep * 1e3:.2f} mm/s"


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
@pytest.mark.parametrize("static_friction", [False, True])
@pytest.mark.parametrize("tilt", [20.0, 25.0])
@pytest.mark.parametrize("young", [3e5, 1e9])
def test_a_rope_beyond_its_friction_angle_slides_at_coulombs_rate(young, tilt, static_friction, cone):
    """tan(20 deg) = 0.36 > mu = 0.3: the rope slides down with g (sin theta - mu cos theta)
    (0.590 m/s^2 at 20 degrees, 1.479 at 25), its centre's speed measured over 10 ms at
    0.2 s and at 0.69 s, within SLIDE_TOL; the same with static friction on or off, and with
    pyramidal or elliptic cones."""
    tilt_rad = math.radians(tilt)
    world = _rope_on_incline(young, tilt_deg=tilt, static_friction=static_friction, cone=cone)
    speeds = []
    for settle in (200, 480):
        world.step(settle)
        p = world.positions().mean(axis=0)
        world.step(10)
        speeds.append(np.linalg.norm(world.positions().mean(axis=0) - p) / 0.01)
    accel = (speeds[1] - speeds[0]) / 0.49
    coulomb = 9.81 * (math.sin(tilt_rad) - 0.3 * math.cos(tilt_rad))
    assert accel == pytest.approx(coulomb, rel=SLIDE_TOL)


@pytest.mark.parametrize("young", [3e5, 1e9])
def test_with_elliptic_cones_a_rope_holds_near_its_friction_angle(young):
    """tan(theta) = 0.95 mu (15.9 degrees): with elliptic cones (friction as Coulomb states
    it) and static friction, the rope holds below CREEP_LIMIT; an anchor whose pull reaches
    the cone is dragged to its limit rather than let go (derods/_numba/friction.py)."""
    tilt = math.degrees(math.atan(0.95 * 0.3))
    world = _rope_on_incline(young, tilt_deg=tilt, static_friction=True, cone="elliptic")
    world.step(200)
    before = world.positions().mean(axis=0)
    world.step(500)
    creep = np.linalg.norm(world.positions().mean(axis=0) - before) / 0.5
    assert creep < CREEP_LIMIT, f"creeps at {creep * 1e3:.2f} mm/s"

