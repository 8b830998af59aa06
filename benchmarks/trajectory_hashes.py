"""Hashed trajectories of rods that no body with dofs holds, per mode: a check that a change
leaves them unchanged to the bit (compare the printout of two checkouts).

Worlds: a rod dropped on mjcf/box.xml (dt 2e-3, 300 steps); a cable on a floor dragged by a
mocap cart, pinned and clamped (dt 5e-3, 200 steps); a coil falling onto itself with
self-collision (dt 2e-3, 300 steps); each in the implicit, alpha and projection modes. A hash
is sha256 over qpos and qvel after every step (first 16 hex digits).

Run: .venv/bin/python benchmarks/trajectory_hashes.py   (in each checkout; diff the outputs)
"""

from __future__ import annotations

import hashlib
import os
import sys

import mujoco
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from derods import ContactParams, Material, Rod, World, shapes  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def digest(world: World, steps: int, before=None) -> str:
    """sha256 of qpos and qvel after each of ``steps`` steps (``before(world, k)`` first)."""
    h = hashlib.sha256()
    for k in range(steps):
        if before is not None:
            before(world, k)
        world.step()
        h.update(world.data.qpos.tobytes())
        h.update(world.data.qvel.tobytes())
    return h.hexdigest()[:16]


def worlds(mode: str):
    """(name, world, steps, before) of every world, in ``mode``."""
    w = World(os.path.join(ROOT, "mjcf", "box.xml"), dt=2e-3, mode=mode)
    w.add_rod(Rod(shapes.straight(0.5, 30, start=(-0.25, 0.02, 0.35)),
                  Material(young=1e7, density=1000.0, radius=4e-3)), "rod")
    yield "drop", w, 300, None
    for end in ("pin", "clamp"):
        spec = mujoco.MjSpec.from_string('<mujoco><worldbody><geom type="plane" size="3 3 .1"/>'
                                         '<body name="cart" mocap="true" pos="0 0 0.004"/></worldbody></mujoco>')
        w = World(spec, dt=5e-3, mode=mode, scene_checks=False)  # the cable lies in the floor on purpose
        w.add_rod(Rod(shapes.straight(0.5, 32, start=(0.0, 0.0, 0.003), direction=(-1.0, 0.0, 0.0)),
                      Material(young=1e7, density=1000.0, radius=3e-3)), "rod", start=end, start_body="cart")

        def drag(world, k):
            world.data.mocap_pos[0, 0] = 0.3 * min(k * 5e-3 / 0.5, 1.0)
        yield f"mocap {end}", w, 200, drag
    t = np.linspace(0.0, 4.0 * np.pi, 80)
    x = np.stack([0.05 * np.cos(t), 0.05 * np.sin(t), 0.3 + 0.004 * t], axis=1)
    w = World(None, dt=2e-3, mode=mode, contact=ContactParams(self_collision=True), gravity=(0.0, 0.0, -9.81))
    w.add_rod(Rod(x, Material(young=1e6, density=1000.0, radius=3e-3)), "coil", start="clamp")
    yield "coil", w, 300, None


def main() -> int:
    for mode in ("implicit", "alpha", "projection"):
        for name, world, steps, before in worlds(mode):
            print(f"{name + ' ' + mode:28s} {digest(world, steps, before)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
