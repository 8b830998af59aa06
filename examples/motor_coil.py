"""A motor winds a clamped rod until it coils into a plectoneme.

Shows: clamps on MuJoCo bodies. One end of a slack rod is clamped to the
world, the other to a disk on a hinge that a position servo turns 10 times.
The twist first bends the rod into a helix, then (with self-contact) the rod
writhes into a plectoneme: two strands wound around each other. The disk
feels the rod's twisting moment through its clamp.
Expected: motor_coil.mp4 (camera close to the coil); the final writhe is
several turns.

Run:   .venv/bin/python examples/motor_coil.py [--out out/examples] [--test]
"""

import argparse
import math
import pathlib

import derods
import mujoco
import numpy as np
from scipy.optimize import brentq

from derods import shapes
from derods.viz import filming, render
from derods import ContactParams, World


def slack_rod(length: float, gap: float, n_edges: int, height: float = 0.5) -> np.ndarray:
    """A rod of ``length`` bowed up between two points ``gap`` apart, leaving both along x."""
    u = np.linspace(0.0, 1.0, 4001)

    def curve(a):
        return np.stack([gap * u, 0 * u, height + a * (1 - np.cos(2 * np.pi * u)) / 2], axis=1)

    def excess(a):
        return np.linalg.norm(np.diff(curve(a), axis=0), axis=1).sum() - length

    return shapes.resample(curve(brentq(excess, 0.0, length)), n_edges)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="a short, coarse run, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n, turns, seconds = (40, 2.0, 0.5) if args.test else (100, 10.0, 8.0)
    gap = 0.6  # m between the clamps, for a 1 m rod
    spec = mujoco.MjSpec()
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    render.add_backdrop(spec)
    spec.worldbody.add_light(pos=[0.3, -0.5, 1.5], dir=[0, 0.3, -1], diffuse=[0.8, 0.8, 0.8])
    motor = spec.worldbody.add_body(name="motor", pos=[gap, 0, 0.5])
    motor.add_joint(name="spin", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1, 0, 0])
    motor.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.05, 0.01, 0], euler=[0, math.pi / 2, 0],
                   mass=2.0, contype=0, conaffinity=0, rgba=[0.3, 0.3, 0.35, 1])
    spec.add_actuator(name="servo", target="spin", trntype=mujoco.mjtTrn.mjTRN_JOINT).set_to_position(
        kp=200.0, kv=20.0)
    world = World(spec, dt=2e-3, gravity=(0, 0, 0), mass_damping=1.0,
                  contact=ContactParams(self_collision=True, friction=0.5))
    rod = derods.Rod(slack_rod(1.0, gap, n), derods.Material(young=2e6, radius=0.004),
                     natural_curvature=False, boundary=derods.TwistBoundary("clamped", 0.0, 0.0))
    world.add_rod(rod, "rod", start="clamp", end="clamp", end_body="motor", rgba=(0.85, 0.3, 0.15, 1))
    world.compile()
    cam = mujoco.MjvCamera()
    cam.lookat[:] = [gap / 2, 0.0, 0.55]
    cam.distance, cam.azimuth, cam.elevation = 0.9, 70.0, -20.0

    def wind(w):
        w.data.ctrl[0] = 2 * math.pi * turns * min(1.0, w.time / (0.75 * seconds))

    size = (320, 180) if args.test else (1280, 720)
    filming.film(world, out / "motor_coil.mp4", seconds, 30.0, size[0], size[1], cam,
                 before_step=wind, progress=not args.test, label="motor coil")
    x = world.positions("rod")
    closed = np.concatenate([x, [[gap, 0, -5.0], [0, 0, -5.0]]])  # closed far below: writhe of the rod
    print(f"{out / 'motor_coil.mp4'}: motor turned {world.data.qpos[0] / (2 * math.pi):.2f} turns, "
          f"writhe {derods.geometry.writhe(closed):.2f} turns")


if __name__ == "__main__":
    main()
