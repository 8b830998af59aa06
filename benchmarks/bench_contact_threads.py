"""The contact stage's blocks on two threads (derods.sim.contact.ContactStep, past
SPLIT_MIN_ROWS rows) against one, same run: R rods of 32 vertices lying on a floor
(bench_world's strands), each world built twice, its contact stage held to one thread or
let take two (``ContactStep._threaded``), runs interleaved; each run is the median of its
timed steps, each figure the median of the runs. Below the threshold both are one call
and read the same; ``--force`` takes two threads at any size (the threshold's evidence).

Run: .venv/bin/python benchmarks/bench_contact_threads.py [--counts 10,30,50,100] [--repeat 3]
     [--steps 200] [--force]
"""

from __future__ import annotations

import argparse

import numpy as np

from bench_world import median_us, strands

def run(count: int, repeat: int, steps: int, force: bool) -> dict:
    der = strands(count, lying=True)[0]
    runs = {False: [], True: []}
    for _ in range(repeat):
        for threaded in (False, True):
            world = der()
            stage = world._step.contact
            stage._threaded = threaded and stage._threaded
            if force and threaded:
                stage._threaded, stage.split_min_rows = True, 0
            runs[threaded].append(median_us(world, steps, 20))
    one, two = float(np.median(runs[False])), float(np.median(runs[True]))
    return {"rods": count, "one_thread_us": one, "two_threads_us": two, "ratio": two / one}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", default="10,30,50,100")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--force", action="store_true", help="two threads whatever the rows")
    args = ap.parse_args()
    print("rods of 32 vertices lying on a floor: median us per step, contact stage on one thread / two")
    for count in (int(c) for c in args.counts.split(",")):
        rec = run(count, args.repeat, args.steps, args.force)
        print(f"  {rec['rods']:4d} rods  {rec['one_thread_us']:9.0f}  {rec['two_threads_us']:9.0f}  "
              f"ratio {rec['ratio']:.2f}", flush=True)


if __name__ == "__main__":
    main()
