"""MuJoCo's own compile time against the number of bodies, no derods involved: the floor
under the hair benchmark's build exponent (issue "hair at scale").

A model of N bodies, each on three slide joints with a sphere (what one rod vertex is in
derods), built from ``<replicate>`` chunks of 1000 bodies merged pairwise with
``MjSpec.attach`` (building it body by body, or parsing one replicate of N, costs N^2
before the compile starts), then ``spec.compile()`` timed alone, ``--repeat`` times,
medians. Prints the compile time per N and its exponent in N.

Measured on this 2-core VM (MuJoCo 4.0.0): the compile grows as N^1.6-1.8. Profiled
(perf), the time goes to ``mj_makeBSparse`` (the body-dof sparsity: the world body's row
holds all nv dofs, gathered in reverse body order and sorted by insertion, nv^2 / 2
moves) and ``mj_validateReferences``; no layout of the bodies avoids the world row.

Run: .venv/bin/python benchmarks/bench_mujoco_compile.py [--bodies 3000,9000,30000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time

import mujoco
import numpy as np

CHUNK = 1000


def chunk() -> mujoco.MjSpec:
    """CHUNK bodies, each on three slides with a 1 mm sphere."""
    return mujoco.MjSpec.from_string(
        f'<mujoco><worldbody><replicate count="{CHUNK}" offset="0.001 0 0"><body>'
        '<joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 1 0"/><joint type="slide" axis="0 0 1"/>'
        '<geom size="0.001" mass="0.001"/></body></replicate></worldbody></mujoco>')


def model_spec(n_bodies: int) -> mujoco.MjSpec:
    """A spec of n_bodies (a multiple of CHUNK) such bodies, merged pairwise."""
    specs = [chunk() for _ in range(max(1, n_bodies // CHUNK))]
    while len(specs) > 1:
        merged = []
        for k in range(0, len(specs) - 1, 2):
            specs[k].attach(specs[k + 1], frame=specs[k].worldbody.add_frame(), prefix=f"m{len(specs)}_{k}_")
            merged.append(specs[k])
        if len(specs) % 2:
            merged.append(specs[-1])
        specs = merged
    spec = specs[0]
    spec.memory = max(64, n_bodies // 10) * 2**20
    return spec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bodies", default="3000,9000,30000")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    sizes = [int(v) for v in args.bodies.split(",")]
    times = {n: [] for n in sizes}
    for _ in range(args.repeat):
        for n in sizes:
            spec = model_spec(n)
            t0 = time.perf_counter()
            model = spec.compile()
            times[n].append(time.perf_counter() - t0)
            assert model.nbody == n + 1 and model.nv == 3 * n
    for n in sizes:
        print(f"{n:>6} bodies ({3 * n} dofs): MuJoCo's compile {np.median(times[n]):.3f} s (median of {args.repeat})")
    if len(sizes) >= 2:
        p = np.polyfit(np.log(sizes), np.log([np.median(times[n]) for n in sizes]), 1)[0]
        print(f"exponent in N ({sizes[0]}..{sizes[-1]}): {p:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
