"""The implicit step's stages as one compiled call each (derods/_numba/implicit_stages.py)
against the same kernels called one by one, same worlds, interleaved runs.

Worlds (bench_world's cases): ``cantilever`` (n = 20), ``hanging`` (one rod of 32 vertices
from a clamp), ``box`` and ``floor`` (drop n = 50), ``lying`` (one rod of 32 vertices on the
floor), ``lying10`` (ten of them). Each is built twice per run, stepping its prediction and
conclusion in one call each or kernel by kernel (``Implicit._in_one_call`` held False);
after ``--warm`` steps, each run is the median of ``--steps`` timed steps, each figure the
median of ``--repeat`` runs, the order alternating. It first checks that both step the same
trajectory to the bit (qpos and qvel after 300 steps).

Run: .venv/bin/python benchmarks/bench_stages.py [--worlds cantilever,hanging,box,floor,lying,lying10]
     [--repeat 6] [--steps 300] [--warm 150]
"""

from __future__ import annotations

import argparse

import numpy as np

from bench_world import cantilever, drop, median_us, strands

WORLDS = {"cantilever": cantilever(20)[0], "hanging": strands(1, lying=False)[0], "box": drop("box")[0],
          "floor": drop("floor")[0], "lying": strands(1, lying=True)[0], "lying10": strands(10, lying=True)[0]}


def build(name: str, one_call: bool):
    world = WORLDS[name]()
    if not one_call:
        world._step._in_one_call = lambda: False
    return world


def same_trajectory(name: str, steps: int = 300) -> bool:
    a, b = build(name, True), build(name, False)
    for _ in range(steps):
        a.step()
        b.step()
    return np.array_equal(a.data.qpos, b.data.qpos) and np.array_equal(a.data.qvel, b.data.qvel)


def run(name: str, repeat: int, steps: int, warm: int) -> dict:
    runs = {True: [], False: []}
    for r in range(repeat):
        for one_call in ((True, False) if r % 2 == 0 else (False, True)):
            world = build(name, one_call)
            world.step(warm)
            runs[one_call].append(median_us(world, steps, 0))
    one, staged = float(np.median(runs[True])), float(np.median(runs[False]))
    return {"world": name, "one_call_us": one, "staged_us": staged, "ratio": one / staged,
            "same": same_trajectory(name)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worlds", default=",".join(WORLDS))
    ap.add_argument("--repeat", type=int, default=6)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--warm", type=int, default=150)
    args = ap.parse_args()
    print("median us per step: stages in one call each / kernel by kernel (same trajectory to the bit?)")
    for name in args.worlds.split(","):
        r = run(name, args.repeat, args.steps, args.warm)
        print(f"  {name:10s} {r['one_call_us']:8.1f} {r['staged_us']:8.1f}  ratio {r['ratio']:.3f}  "
              f"same: {r['same']}", flush=True)


if __name__ == "__main__":
    main()
