"""Rods dropped onto every scene of mjcf/: floor, box, table_edge, stairs, pegs, halfpipe, rail.

Shows: free rods falling under gravity onto rigid obstacles and coming to rest
draped over them (contact and friction from MuJoCo, elasticity from derods).
Expected: one MP4 per scene in the output folder; the rods land, bend over
edges, pegs and rails, and stop moving within a few seconds.

Run:   .venv/bin/python examples/drop_scenes.py [--out out/examples] [--test]
"""

import argparse
import pathlib

import derods  # noqa: F401  (chooses a headless OpenGL backend before MuJoCo loads one)
from derods import scenes
from derods.apps import drop


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="a few frames per scene, small, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for scene in scenes.names():
        if args.test:
            p = drop.DropParams(scene=scene, rods=2, n_edges=12, seconds=0.3, fps=10, width=160, height=90,
                                dt=5e-3)
        else:
            p = drop.DropParams(scene=scene, rods=4, seconds=4.0)
        info = drop.drop(p, out / f"drop_{scene}.mp4", progress=not args.test)
        print(f"{scene}: {info['out']} ({info['frames']} frames)")


if __name__ == "__main__":
    main()
