"""Rods clamped to bodies of any mass: stability of the coupled step over body mass,
stiffness and resolution (issue "rods coupled to MuJoCo bodies of any mass").

A rod (L = 1 m, r = 1 cm, rho = 1000 kg/m^3: 0.31 kg) clamped to the world at one end
and to a body at the other, the body on a slide joint along the rod, on a free joint or
on an arm turning about a vertical hinge 0.1 m beyond the tip
(:func:`derods.bench.coupling.clamped_world`), moved 1e-6 m from rest and stepped 300
times at dt (:func:`derods.bench.coupling.perturbed`: stable = no divergence, and the
energy, elastic and kinetic, never above 1.01 times its start). Prints one line per
(scene, n, E, mass) and the count of unstable runs. Target: none, at dt = 1e-2, for bodies of 1e-3 to
1e4 kg, n = 20 and 100, E = 1e5 to 1e10.

Run: .venv/bin/python benchmarks/bench_holders.py [--n 20,100] [--young 1e5,...,1e10]
     [--mass 1e-3,...,1e4] [--dt 1e-2] [--mode implicit]
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from derods import bench  # noqa: E402
from derods.bench import coupling  # noqa: E402


def floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=",".join(coupling.SCENES))
    ap.add_argument("--n", default="20,100")
    ap.add_argument("--young", default="1e5,1e6,1e7,1e8,1e9,1e10")
    ap.add_argument("--mass", default=",".join(f"{m:g}" for m in coupling.SWEEP_MASSES))
    ap.add_argument("--dt", type=float, default=1e-2)
    ap.add_argument("--mode", default="implicit")
    args = ap.parse_args()
    unstable = 0
    runs = list(itertools.product(args.scene.split(","), [int(v) for v in args.n.split(",")], floats(args.young),
                                  floats(args.mass)))
    for scene, n, young, mass in runs:
        p = bench.CaseParams(n_edges=n, dt=args.dt, young=young, mode=args.mode)
        t0 = time.perf_counter()
        r = coupling.perturbed(p, scene, mass)
        wall = time.perf_counter() - t0
        unstable += not r["stable"]
        print(f"{scene:5s} n={n:3d} E={young:7.0e} Pa body {mass:7.0e} kg: "
              f"{'stable  ' if r['stable'] else 'UNSTABLE'} peak {r['peak']:.2e} m energy {r['energy']:.4f} of its start "
              f"{1e3 * wall / 300:6.2f} ms/step "
              f"{r['note']}", flush=True)
    print(f"{unstable} of {len(runs)} runs unstable at dt = {args.dt:g} s")
    return 1 if unstable else 0


if __name__ == "__main__":
    sys.exit(main())
