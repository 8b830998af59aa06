"""Michell's instability of a twisted ring.

Shows: a naturally straight ring with total twist Theta stays planar below
Theta_c = 2 pi sqrt(3) alpha / beta and buckles out of plane above it
(Goriely 2006; Bergou et al. 2008, section 7).
Expected: the bisected critical twist within 2 % of Theta_c at 50 edges
(+1.27 % measured), and michell.png: a planar ring at 0.9 Theta_c beside a
figure-eight ring at 1.2 Theta_c.

Run:   .venv/bin/python examples/michell.py [--out out/examples] [--test]
"""

import argparse
import pathlib

import derods  # noqa: F401
from derods import bench
from derods.viz import figures


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--test", action="store_true", help="a coarse ring, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    n = 20 if args.test else 50
    for ratio in ((1.0,) if args.test else (0.5, 1.0, 2.0)):
        p = bench.CaseParams(n_edges=n, young=1e7, radius=0.005, shear=ratio * 1e7 / 2)
        rec, = bench.michell(p)
        print(f"beta/alpha = {ratio:g}: critical twist {rec['measured']:.3f} rad, "
              f"Michell {rec['reference']:.3f} rad ({100 * rec['rel_error']:+.2f} %)")
    info = figures.michell_pair(out / "michell.png", n_edges=n, seconds=2.0 if args.test else 4.0,
                                width=320 if args.test else 960, height=160 if args.test else 480)
    print(f"{info['out']}: out of plane {1000 * info['out_of_plane'][0]:.2f} mm (below) and "
          f"{1000 * info['out_of_plane'][1]:.2f} mm (above)")


if __name__ == "__main__":
    main()
