"""Grasping a rod by contact and friction (examples/grasp.py, mjcf/gripper.xml): the
fingers' dofs join derods' contact solve (derods/sim/contact.py)."""

from __future__ import annotations

import numpy as np
import pytest
import rods


@pytest.fixture(scope="module")
def grasp():
    return rods.example("grasp")


@pytest.fixture(scope="module")
def result(grasp):
    return grasp.run()


def test_the_cable_does_not_slip_in_the_fingers(grasp, result):
    """Lifted and carried 0.55 m, the point the pads hold stays put along the cable: within
    a third of its radius (2 mm; measured 0.75 mm): the friction cone holds its weight and
    the carry's accelerations."""
    assert result["slip"] < grasp.MATERIAL.radius / 3


def test_the_pads_do_not_squeeze_into_the_cable(grasp, result):
    """The deepest pad contact stays within a quarter of the cable's radius (1.5 mm;
    measured 0.09 mm), though the servos would close the fingers to 0."""
    assert 0 < result["depth"] < grasp.MATERIAL.radius / 4


def test_the_lifting_servo_feels_the_cables_weight(grasp, result):
    """Held still, the lifting servo pushes harder than for the empty gripper by the
    cable's weight, to 2 % (measured 0.07 %: the servo's own settling)."""
    assert result["felt"] == pytest.approx(result["weight"], rel=2e-2)


def test_the_cable_is_left_on_the_peg(grasp, result):
    """Released over the peg, the cable rests on its top: its vertex above the peg's axis
    at the peg's top plus its radius, to 1 mm."""
    x = result["cable"]
    on_peg = x[np.argmin(np.abs(x[:, 0] - grasp.PEG[0])), 2]
    assert on_peg == pytest.approx(grasp.PEG[1] + grasp.MATERIAL.radius, abs=1e-3)


def test_without_the_fingers_in_the_contact_solve_the_pads_squeeze_through(grasp, monkeypatch):
    """The test can fail: with the fingers' rows left to MuJoCo (its force computed for a
    bare 2 g vertex), the servos close the fingers through the cable and nothing is lifted."""
    from derods.sim import contact

    init = contact.ContactStep.__init__

    def without_trees(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.bodies = False

    monkeypatch.setattr(contact.ContactStep, "__init__", without_trees)
    world = grasp.build()
    drive = grasp.Grasp(world)
    while world.time < 2.8:
        drive(world)
        world.step()
    assert world.data.qpos[world.model.joint("fl").qposadr[0]] < 1e-3  # closed through the cable
    assert world.positions("cable")[:, 2].max() < 0.42  # still on the table
