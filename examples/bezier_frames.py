"""Bishop frames on a rod built from cubic Bezier segments, joined C1 and C0.

Shows: the DER paper's first experiment. The Bishop (twist-free) frame is
parallel-transported along the rod: its normal u (pink) and binormal v (green)
turn only as much as the tangent does.
Expected: frames_C1.png, where the frames turn smoothly through the join (dark
sphere), and frames_C0.png, where they jump with the corner at the join.

Run:   .venv/bin/python examples/bezier_frames.py [--out out/examples] [--test]
"""

import argparse
import pathlib

import derods  # noqa: F401
from derods.viz import figures


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="small pictures, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = (320, 200) if args.test else (960, 640)
    for continuity in ("C1", "C0"):
        info = figures.bezier_frames(out / f"frames_{continuity}.png", continuity=continuity,
                                     width=size[0], height=size[1])
        print(f"{continuity}: {info['out']}, largest turning angle {info['max_turn_deg']:.1f} deg")


if __name__ == "__main__":
    main()
