"""Microseconds per evaluation of the DER core: forces + Hessian + twist solve.

What one implicit step of the MuJoCo coupling needs from the core
(:meth:`derods.Rod.step_terms`), for an isotropic rod clamped at both ends (so
the twist term is active): transport the reference frames to the new
positions, solve the quasistatic twist, evaluate the gradient of every active
term and its positive semi-definite Hessian in scipy's lower banded form (plus
the rank-one twist term). Timed twice: the compiled kernel, and the numpy
path it replaces (the reference the kernel is tested against).

Cases: one rod of 20, 200 and 2000 vertices; 1000 rods of 32 vertices in one
batched call. Each figure is the median over repeated timed calls (machines
are shared and noisy: compare medians, never single runs).

Run: make bench   (or: .venv/bin/python benchmarks/bench_core.py [--repeat N])
Targets (DER core issue, 2-core machine): <= 150 us for one 200-vertex rod,
<= 50 ms for 1000 x 32.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import derods
from derods import shapes
from derods.twist import TwistBoundary


def make_case(n_vertices: int, n_rods: int, rng):
    mat = derods.Material(young=1e8, radius=0.01)
    rest = shapes.straight(1.0, n_vertices - 1)
    if n_rods > 1:
        rest = np.broadcast_to(rest, (n_rods,) + rest.shape).copy()
    rod = derods.Rod(rest, mat, boundary=TwistBoundary("clamped", 0.0, 1.0))
    state = rod.rest_state()
    # A bent, twisted configuration: a gentle helix-like perturbation.
    s = np.linspace(0, 1, n_vertices)
    x = rod.rest_x + 0.05 * np.stack([0 * s, np.sin(3 * s), 1 - np.cos(2 * s)], axis=-1)
    x = x + rng.normal(scale=1e-4, size=x.shape)
    return rod, state, x


def step(rod, state, x, use_kernel):
    return rod.step_terms(state, x, use_kernel=use_kernel)


def time_case(n_vertices, n_rods, repeat, rng, use_kernel):
    rod, state, x = make_case(n_vertices, n_rods, rng)
    for _ in range(max(3, repeat // 10)):
        step(rod, state, x, use_kernel)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        step(rod, state, x, use_kernel)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e6, rod.active_terms


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=300, help="timed calls per case")
    ap.add_argument("--json", action="store_true", help="print one JSON object per case")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    cases = [(20, 1), (200, 1), (2000, 1), (32, 1000)]
    targets = {(200, 1): 150.0, (32, 1000): 50_000.0}
    print(f"derods {derods.__version__}, numpy {np.__version__}")
    print(f"{'case':>18} {'kernel us':>10} {'numpy us':>10} {'numpy/kernel':>12} {'target us':>10}"
          "  active terms")
    for nv, nr in cases:
        reps = args.repeat if nv * nr <= 2000 else max(20, args.repeat // 10)
        us_k, terms = time_case(nv, nr, reps, rng, True)
        us_n, _ = time_case(nv, nr, max(10, reps // 4), rng, False)
        tgt = targets.get((nv, nr))
        label = f"{nr} x {nv} vertices"
        if args.json:
            print(json.dumps({"n_rods": nr, "n_vertices": nv, "us_kernel": us_k, "us_numpy": us_n,
                              "target_us": tgt, "active_terms": terms}))
        else:
            print(f"{label:>18} {us_k:10.1f} {us_n:10.1f} {us_n / us_k:12.1f} {tgt or '':>10}"
                  f"  {','.join(terms)}")


if __name__ == "__main__":
    main()
