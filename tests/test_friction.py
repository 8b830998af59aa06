"""Static friction: a rod resting on an incline below its friction angle stays put.

Coulomb: a body on a plane tilted by theta holds while
tan(theta) < mu, without creeping. cosseratbench's capstan asks the same of a
heavy rope over a cylinder (below the holding overhang it must move < 1 mm in
2 s); derods' rope creeps there, and this is the smallest case that shows it.

What is known (E = 3e5 Pa, dt = 1e-3, ContactParams' defaults): MuJoCo's own solve
of the same rows (mode="projection", bare vertex masses) creeps 1.6 mm/s, the soft
friction of its impedance d = 0.9. derods' rows creep 7.7 mm/s: their weights
(derods/_numba/contact.py: row_weights) keep MuJoCo's R / diagA but put the Delassus
diagonal of the implicit metric under them (68,400 here, the bare masses' exact one
is 69,400), while MuJoCo's diagA for these
flex contacts is an approximation 5.6x lower (12,490), so derods' rows come out 5.5x
softer than MuJoCo's. With the impedance raised to 0.9999 the creep falls only to
3.3-3.8 mm/s (solref 2-5 ms), and there the friction cone is the cause: of each
contact's four pyramidal rows (n +- mu t1, n +- mu t2, t2 along the slope) the pair
across the slope carries two fifths of the normal force (their rows see the same
penetration) and no friction along it, and the uphill edge of the other pair is
inactive, so friction along the slope tops out at |f_t| / f_n = 0.176 = tan(10 deg)
against mu = 0.3 and the rope slides at that balance. An elliptic cone, whose friction
reaches mu N in any direction, is the fix (derods leaves elliptic rows to MuJoCo's own
solve today).
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


def _rope_on_incline(young: float, tilt_deg: float = 10.0, friction: float = 0.3, dt: float = 1e-3) -> World:
    """A 0.2 m rope (r = 1 mm, 20 edges) lying along the slope of a plane tilted by tilt_deg."""
    tilt = math.radians(tilt_deg)
    normal = np.array([-math.sin(tilt), 0.0, math.cos(tilt)])
    along = np.array([math.cos(tilt), 0.0, math.sin(tilt)])
    spec = mujoco.MjSpec()
    plane = spec.worldbody.add_geom()
    plane.type = mujoco.mjtGeom.mjGEOM_PLANE
    plane.size = [0.0, 0.0, 1.0]
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, normal)
    plane.quat = quat
    plane.friction = [friction, 0.0, 0.0]
    radius = 1e-3
    world = World(spec, dt=dt, gravity=(0.0, 0.0, -9.81), mode="implicit", contact=ContactParams(friction=friction))
    material = derods.Material(young=young, radius=radius, density=1000.0)
    world.add_rod(derods.Rod(shapes.straight(0.2, 20, start=normal * radius, direction=along), material,
                             stretch_stiffness=material.stretch_stiffness))
    return world


@pytest.mark.xfail(strict=True, reason="derods' contact solve lets resting friction creep: 7.7 mm/s on a 10 degree "
                                       "incline at mu = 0.3 (E = 3e5 Pa), 1.5 mm/s at E = 1e9 (0 on the flat): the pyramidal "
                                       "rows' friction along the slope tops out at tan(10 deg); elliptic "
                                       "cones in derods' contact solve will fix it (see the docstring)")
@pytest.mark.parametrize("young", [3e5, 1e9])
def test_a_rope_on_an_incline_below_its_friction_angle_holds(young):
    """tan(10 deg) = 0.18 < mu = 0.3: after settling for 0.2 s, the rope's centre moves
    less than CREEP_LIMIT along the slope over the next 0.5 s."""
    world = _rope_on_incline(young)
    world.step(200)
    before = world.positions().mean(axis=0)
    world.step(500)
    creep = np.linalg.norm(world.positions().mean(axis=0) - before) / 0.5
    assert creep < CREEP_LIMIT, f"creeps at {creep * 1e3:.2f} mm/s"
