"""A two-finger gripper picks a cable off a table, carries it over a peg and lets go.

Shows: grasping by contact and friction, no clamp. The gripper (mjcf/gripper.xml) is
ordinary MuJoCo: a palm on two position-servoed slides and two position-servoed
fingers with rubber pads. The cable is a derods rod lying on the table; the pads hold
it only by their squeeze and friction. The fingers' dofs join derods' contact solve in
the steps they touch the cable (derods/sim/contact.py), so the pads feel the cable's
stiffness and the cable the fingers' inertia and servos at once.
Expected: grasp.mp4; the cable rises with the fingers, hangs from them while carried,
drapes over the peg when released. Printed: how far the cable slipped in the fingers
while carried, how deep it went into the pads, and the weight the lifting servo felt
against the cable's.

Run:   .venv/bin/python examples/grasp.py [--out out/examples] [--test]
"""

from __future__ import annotations

import argparse
import pathlib

import mujoco
import numpy as np

import derods
from derods import ContactParams, World, geometry, scenes, shapes
from derods.viz import filming

#: The cable: 0.6 m, 6 mm radius, E = 2e7 Pa (a soft rubber cable), 40 edges.
CABLE = dict(length=0.6, n_edges=40)
MATERIAL = derods.Material(young=2e7, radius=0.006, density=1100.0)
#: The palm's offsets from its start [m] and the fingers' targets [m] over time [s]:
#: (time, x, z, fingers). Linear between the rows.
PLAN = np.array([
    (0.0, 0.0, 0.0, 0.04),     # above the cable, fingers open
    (0.6, 0.0, 0.0, 0.04),     # the cable settles on the table
    (1.4, 0.0, -0.24, 0.04),   # down: pads around the cable
    (1.8, 0.0, -0.24, 0.0),    # close (the pads stop on the cable)
    (2.8, 0.0, 0.0, 0.0),      # lift 0.24 m
    (4.2, 0.55, 0.0, 0.0),     # carry over the peg
    (4.8, 0.55, 0.0, 0.0),     # hold still: the servo feels the cable's weight
    (5.2, 0.55, -0.04, 0.0),   # lower it to just above the peg
    (5.5, 0.55, -0.04, 0.04),  # open
    (6.5, 0.55, -0.04, 0.04),  # the cable drapes over the peg
])
#: The peg's axis x [m] and top z [m] (mjcf/gripper.xml).
PEG = (0.35, 0.55)
HOLD = (4.3, 4.8)  # the still window [s] in which the weight is measured
CARRY = (2.9, 4.8)  # lifted and carried [s]: the cable must not slip


def build() -> World:
    """The gripper scene with the cable lying on the table under the palm."""
    world = World(scenes.path("gripper"), dt=2e-3, mass_damping=1.0,
                  contact=ContactParams(friction=1.0, condim=4))
    x = shapes.straight(CABLE["length"], CABLE["n_edges"])
    x -= x.mean(axis=0)
    x += (-0.2, 0.0, 0.4 + MATERIAL.radius + 1e-4)
    world.add_rod(derods.Rod(x, MATERIAL), "cable", rgba=(0.85, 0.35, 0.15, 1))
    world.compile()
    return world


def targets(t: float) -> tuple[float, float, float]:
    """The palm's x and z offsets [m] and the fingers' target [m] at time t [s]."""
    return tuple(float(np.interp(t, PLAN[:, 0], PLAN[:, k])) for k in (1, 2, 3))


class Grasp:
    """Drives the gripper through PLAN and measures what the issue asks: slip of the
    cable in the fingers, penetration into the pads, the weight the lifting servo feels."""

    def __init__(self, world: World):
        self.world = world
        m = world.model
        self.act = {name: m.actuator(name).id for name in ("move_x", "move_z", "finger_l", "finger_r")}
        self.pad_ids = (m.geom("pad_l").id, m.geom("pad_r").id)
        self.pads = set(self.pad_ids)
        self.z_force, self.grip_offset, self.depth = [], [], []

    def __call__(self, world: World) -> None:
        """Before each step: measure the state the last step left, then set the targets."""
        self.measure(world)
        x, z, f = targets(world.time)
        ctrl = world.data.ctrl
        ctrl[self.act["move_x"]], ctrl[self.act["move_z"]] = x, z
        ctrl[self.act["finger_l"]] = ctrl[self.act["finger_r"]] = f

    def measure(self, world: World) -> None:
        d, t = world.data, world.time
        if HOLD[0] <= t <= HOLD[1]:
            self.z_force.append(float(d.actuator_force[self.act["move_z"]]))
        if CARRY[0] <= t <= CARRY[1]:
            # where along the cable the pads hold it: the arc length [m] of the cable's
            # closest point to the point between the pads
            x = world.positions("cable")
            mid = 0.5 * (d.geom_xpos[self.pad_ids[0]] + d.geom_xpos[self.pad_ids[1]])
            self.grip_offset.append(geometry.arc_length_to(x, mid))
            for c in d.contact[: d.ncon]:
                if set(c.geom) & self.pads:
                    self.depth.append(-c.dist)

    def summary(self, empty_weight: float) -> dict:
        """slip [m]: how far the grip point moved along the cable while carried; depth [m]:
        deepest penetration into a pad; felt [N]: the lifting servo's extra force while
        still, against the cable's weight."""
        rod_weight = MATERIAL.line_density * CABLE["length"] * 9.81
        return {"slip": float(np.ptp(self.grip_offset)) if self.grip_offset else np.inf,
                "depth": max(self.depth, default=0.0),
                "felt": float(np.mean(self.z_force)) - empty_weight,
                "weight": rod_weight}


def empty_gripper_force() -> float:
    """The lifting servo's force [N] holding the gripper alone, still, at the hold pose."""
    m = mujoco.MjModel.from_xml_path(str(scenes.path("gripper")))
    d = mujoco.MjData(m)
    x, z, f = targets(HOLD[1])
    d.ctrl[m.actuator("move_x").id], d.ctrl[m.actuator("move_z").id] = x, z
    d.ctrl[m.actuator("finger_l").id] = d.ctrl[m.actuator("finger_r").id] = f
    for _ in range(2000):
        mujoco.mj_step(m, d)
    return float(d.actuator_force[m.actuator("move_z").id])


def run(seconds: float | None = None, out: pathlib.Path | None = None, size=(1280, 720)) -> dict:
    """Run the plan (``seconds``: all of it by default), filming to ``out`` if given."""
    world = build()
    grasp = Grasp(world)
    seconds = PLAN[-1, 0] if seconds is None else seconds
    filming.step_or_film(world, seconds, grasp, out, size)
    out = grasp.summary(empty_gripper_force())
    out["cable"] = world.positions("cable").copy()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="a small video, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = (320, 180) if args.test else (1280, 720)
    s = run(out=out / "grasp.mp4", size=size)
    x = s["cable"]
    on_peg = x[np.argmin(np.abs(x[:, 0] - PEG[0])), 2]
    print(f"wrote {out / 'grasp.mp4'}: slip {1e3 * s['slip']:.2f} mm while carried, deepest in a pad "
          f"{1e3 * s['depth']:.2f} mm (r = {1e3 * MATERIAL.radius:g} mm), the servo felt {s['felt']:.3f} N "
          f"of the cable's {s['weight']:.3f} N; it rests on the peg at z = {on_peg:.4f} m (peg top + r = "
          f"{PEG[1] + MATERIAL.radius:.4f} m)")


if __name__ == "__main__":
    main()
