"""An overhand knot tied in a rope and pulled tight by both ends.

Shows: self-contact. The rope is a naturally straight rod laid out as a loose
overhand knot (a trefoil opened at its outermost lobe); its ends are pinned
to two mocap bodies that move apart. MuJoCo's flex self-collision finds the
contacts between strands; derods solves them in the metric of its implicit
step, so the strands slide on each other and never pass through.
Expected: knot.mp4; the loop closes into a tight knot that stays knotted.

Run:   .venv/bin/python examples/knot.py [--out out/examples] [--test]
"""

import argparse
import pathlib

import derods
import mujoco
import numpy as np

from derods import shapes
from derods.viz import filming, render
from derods import ContactParams, World


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="a short run, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    x = shapes.overhand_knot()
    spec = mujoco.MjSpec()
    render.add_backdrop(spec)
    spec.worldbody.add_light(pos=[0, 0, 1.5], dir=[0, 0, -1], diffuse=[0.8, 0.8, 0.8])
    for name, p in (("left", x[0]), ("right", x[-1])):
        b = spec.worldbody.add_body(name=name, pos=p, mocap=True)
        b.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.008, 0, 0], contype=0, conaffinity=0,
                   rgba=[0.3, 0.3, 0.35, 1])
    world = World(spec, dt=2e-3, gravity=(0, 0, 0), mass_damping=2.0,
                  contact=ContactParams(self_collision=True, friction=0.3))
    rope = derods.Rod(x, derods.Material(young=5e6, radius=0.003), natural_curvature=False)
    world.add_rod(rope, "rope", start="pin", end="pin", start_body="left", end_body="right",
                  rgba=(0.2, 0.5, 0.85, 1))
    world.compile()
    # Pull the ends apart along the line through them, so the knot stays in view.
    chord = (x[-1] - x[0]) / np.linalg.norm(x[-1] - x[0])
    away = [-chord, chord]

    def pull(w):
        d = 0.15 * min(max(0.0, w.time - 0.1), 1.2)  # 0.15 m/s each way for 1.2 s, then hold
        w.data.mocap_pos[0] = x[0] + away[0] * d
        w.data.mocap_pos[1] = x[-1] + away[1] * d

    cam = mujoco.MjvCamera()
    cam.lookat[:] = x[len(x) // 2]
    cam.distance, cam.azimuth, cam.elevation = 0.5, 90.0, -70.0
    seconds = 0.3 if args.test else 2.0
    size = (320, 180) if args.test else (1280, 720)
    filming.film(world, out / "knot.mp4", seconds, 30.0, size[0], size[1], cam, before_step=pull,
                 progress=not args.test, label="knot")
    p = world.positions("rope")
    e0, e1 = p[:-1], p[1:]
    i, j = np.triu_indices(len(e0), k=3)
    mids = 0.5 * (e0 + e1)
    closest = np.min(np.linalg.norm(mids[i] - mids[j], axis=1))
    print(f"{out / 'knot.mp4'}: ends {np.linalg.norm(x[-1] - x[0]):.3f} m -> "
          f"{np.linalg.norm(p[-1] - p[0]):.3f} m apart; closest non-neighbour edge midpoints "
          f"{1000 * closest:.1f} mm (diameter {2000 * rope.material.radius:.0f} mm)")


if __name__ == "__main__":
    main()
