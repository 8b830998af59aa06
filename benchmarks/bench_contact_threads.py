"""The contact stage's blocks on two threads (derods.sim.contact.ContactStep, past
SPLIT_MIN_ROWS rows) against one, same run: R rods of 32 vertices lying on a floor
(bench_world's strands), each world built twice, its contact stage held to one thread or
let take two (``ContactStep._threaded``), runs interleaved; each run is the median of its
timed steps, each figure the median of the runs. Below the threshold both are one call
and read the same; ``--force`` takes two threads at any size (the threshold's evidence).

``--idle`` times the hand-off itself instead: one step's blocks of ten lying rods solved in
two halves, the second on the worker thread, after the stepping thread has been busy alone
for a while (as a step's other stages keep it: the worker idles meanwhile), against the
halves back to back; it prints each half's time, the worker's start delay and the wall.

Run: .venv/bin/python benchmarks/bench_contact_threads.py [--counts 10,30,50,100] [--repeat 3]
     [--steps 200] [--force] [--idle 0,100,300,700,1000,2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import derods._numba.contact as _k
from bench_world import median_us, strands
from derods._numba import parallel
from derods.sim import contact as stage

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


def _busy(us: float) -> None:
    """Keep this thread busy for ``us`` microseconds (the worker thread idles meanwhile)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < us * 1e-6:
        pass


def idle_handoffs(gaps: list[float], calls: int = 200) -> list[dict]:
    """One step's blocks of ten lying rods (settled 40 steps) in two halves, the second on
    the worker thread, each hand-off after ``gap`` us of this thread busy alone; per gap the
    medians [us] of: this thread's half, the worker's start delay and half, and the wall.
    The first record (gap None) is both halves on this thread, back to back."""
    world = strands(10, lying=True)[0]()
    world.step(40)
    step, data = world._step, world.data
    contact = step.contact
    efc = contact.rows(data)
    rest = (contact.local_of_dof, contact.dof_off, stage.WINDOW, step.system.arrays, step.a0, contact.a,
            contact.force, stage.MAX_ITER, stage.TOL)
    blocks = _k.contact_blocks(efc, stage.SUPPORTED, *rest[:2], *rest[3:7])
    n = blocks.n_blocks
    mid = stage.split_blocks(blocks.start, blocks.row_start, 0)

    def half(b0: int, b1: int) -> float:
        t0 = time.perf_counter()
        _k.solve_blocks(efc, None, blocks, b0, b1, *rest)
        return (time.perf_counter() - t0) * 1e6

    def on_worker(t_handed: float) -> tuple[float, float]:
        return (time.perf_counter() - t_handed) * 1e6, half(mid, n)

    pool = parallel.workers()
    for _ in range(20):
        half(0, n)
        pool.submit(half, mid, n).result()
    records = [{"gap_us": None, "first_us": float(np.median([half(0, mid) for _ in range(calls)])),
                "second_us": float(np.median([half(mid, n) for _ in range(calls)]))}]
    records[0]["wall_us"] = records[0]["first_us"] + records[0]["second_us"]
    for gap in gaps:
        first, delay, second, wall = (np.empty(calls) for _ in range(4))
        for k in range(calls):
            _busy(gap)
            t0 = time.perf_counter()
            job = pool.submit(on_worker, t0)
            first[k] = half(0, mid)
            delay[k], second[k] = job.result()
            wall[k] = (time.perf_counter() - t0) * 1e6
        records.append({"gap_us": gap, "first_us": float(np.median(first)), "delay_us": float(np.median(delay)),
                        "second_us": float(np.median(second)), "wall_us": float(np.median(wall))})
    return records


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--counts", default="10,30,50,100")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--force", action="store_true", help="two threads whatever the rows")
    ap.add_argument("--idle", default=None, help="time the hand-off after these gaps [us] instead")
    args = ap.parse_args()
    if args.idle is not None:
        recs = idle_handoffs([float(g) for g in args.idle.split(",")])
        print("ten lying rods' blocks in two halves, us (medians): this thread's half, the worker's "
              "start delay and half, wall")
        for r in recs:
            if r["gap_us"] is None:
                print(f"  one thread, back to back   {r['first_us']:6.0f} + {r['second_us']:6.0f} = "
                      f"{r['wall_us']:6.0f}")
            else:
                print(f"  worker idle {r['gap_us']:6.0f} us    {r['first_us']:6.0f}   {r['delay_us']:6.0f}   "
                      f"{r['second_us']:6.0f}   {r['wall_us']:6.0f}")
        return
    print("rods of 32 vertices lying on a floor: median us per step, contact stage on one thread / two")
    for count in (int(c) for c in args.counts.split(",")):
        rec = run(count, args.repeat, args.steps, args.force)
        print(f"  {rec['rods']:4d} rods  {rec['one_thread_us']:9.0f}  {rec['two_threads_us']:9.0f}  "
              f"ratio {rec['ratio']:.2f}", flush=True)


if __name__ == "__main__":
    main()
