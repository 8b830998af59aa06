"""Rods on threads: each world stepped with its rods in one chunk and in one chunk a thread,
in turn, in one process, and what the threads gain.

The per-rod kernels (:mod:`derods._numba.parallel`: the rods' terms and band, the
implicit solve, the strain limit) give the same results to the bit either way, so one
world serves both: blocks of ``--block`` steps alternate serial / parallel (the order
swapped every block) ``--blocks`` times, and each figure is the median step of its mode.
Inside the steps, the time in the three kernels is summed apart: of the serial step, the
kernels' share f is what threads divide, and the rest (MuJoCo's collision and
integration, the contact solve, the divergence guard) is what they do not. Amdahl's law
then extrapolates the speed-up to p cores, 1 / ((1 - f) + f / s_p) with the kernels'
own speed-up s_p taken as p (the 2-core figure measured says how close they come).

Cases:

* hair: ``--strands`` x ``--vertices`` curled strands on a shaken head
  (:func:`derods.hair.build`, dt = 1e-2 s; issue 24's 1000 x 32 at >= 15 steps/s);
* pile: ``--cables`` cables of 41 vertices falling into a heap
  (:mod:`derods.bench.pile`, implicit steps of 1/120 s), its steps in contact dominated
  by the contact solve, which stays serial;
* sizes: ``--counts`` R straight rods of 32 vertices hanging from clamps (dt = 1e-2 s):
  the smallest world the parallel kernels pay for, against which
  ``derods._numba.parallel.MIN_CHUNK_VERTICES`` is set.

Run: .venv/bin/python benchmarks/bench_parallel.py [--cases hair,pile,sizes] [--blocks 8]
     [--block 5] [--strands 1000] [--vertices 32] [--cables 16] [--counts 4,16,64,128,256]
     [--json FILE]
The machine's other work makes threads wait for one another: read the medians of a
quiet run, and the same-run ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import derods  # noqa: E402
from derods import hair as hair_mod  # noqa: E402
from derods import shapes  # noqa: E402
from derods._numba import parallel  # noqa: E402
from derods.bench import pile as pile_mod  # noqa: E402


class Timed:
    """A world's call of a per-rod kernel (:func:`derods._numba.parallel.kernel`) whose time
    is summed into ``total`` [s]."""

    def __init__(self, inner):
        self.inner, self.total = inner, 0.0

    def __call__(self, *args):
        t0 = time.perf_counter()
        try:
            return self.inner(*args)
        finally:
            self.total += time.perf_counter() - t0


def splits(world):
    """The world's step and its two splits: one chunk (serial) and one a thread (parallel),
    whatever the world's size."""
    st = world._step
    args = (st.rods.v_off, st.layout.dof_off, st.rod_tw)
    return st, parallel.split(*args, 1), parallel.split(*args, parallel.threads())


def compare(world, advance, blocks: int, block: int) -> dict:
    """Median step [ms] and kernel time [ms] a step, serial and parallel, of ``world``
    advanced by ``advance()`` (one step), the modes alternating by blocks."""
    st, serial, par = splits(world)
    times = {False: [], True: []}
    kernel = {False: [], True: []}
    for use in (False, True):  # warm both
        st.use_split(par if use else serial)
        advance()
    for b in range(blocks):
        for use in ((False, True) if b % 2 == 0 else (True, False)):
            st.use_split(par if use else serial)
            wrapped = [Timed(st._rods_step), Timed(st._unconstrained_step), Timed(st._limit_kernel)]
            st._rods_step, st._unconstrained_step, st._limit_kernel = wrapped
            for _ in range(block):
                k0 = sum(w.total for w in wrapped)
                t0 = time.perf_counter()
                advance()
                times[use].append(time.perf_counter() - t0)
                kernel[use].append(sum(w.total for w in wrapped) - k0)
    out = {"n_rods": int(st.rods.n_rods), "n_vertices": int(st.rods.n_vertices), "chunks": len(par.rods) - 1,
           "threads": parallel.threads()}
    for use, name in ((False, "serial"), (True, "parallel")):
        out[f"{name}_ms"] = float(np.median(times[use])) * 1e3
        out[f"{name}_kernels_ms"] = float(np.median(kernel[use])) * 1e3
    t1, k1 = out["serial_ms"], out["serial_kernels_ms"]
    out["speedup"] = t1 / out["parallel_ms"]
    out["kernel_speedup"] = k1 / out["parallel_kernels_ms"]
    out["kernel_share"] = k1 / t1
    out["amdahl"] = {p: 1.0 / ((1.0 - k1 / t1) + (k1 / t1) / p) for p in (2, 4, 8, 16)}
    out["amdahl_limit"] = t1 / (t1 - k1)
    return out


def hair_case(args) -> dict:
    world = hair_mod.build(hair_mod.Hair(strands=args.strands, vertices=args.vertices), dt=1e-2)
    world.compile()
    drive = hair_mod.drive(world, hair_mod.Motion("shake"))

    def advance():
        drive(world)
        world.step()

    return {"case": f"hair {args.strands} x {args.vertices}", **compare(world, advance, args.blocks, args.block)}


def pile_case(args) -> dict:
    world = pile_mod.build(pile_mod.PileCase(cables=args.cables, vertices=41, dt=1.0 / 120.0))
    return {"case": f"pile {args.cables} x 41", **compare(world, world.step, args.blocks, args.block)}


def hanging(count: int) -> derods.World:
    mat = derods.Material(young=1e8, radius=0.002)
    world = derods.World(dt=1e-2, mass_damping=2.0)
    for i in range(count):
        world.add_rod(derods.Rod(shapes.cantilever(0.31, 31, start=(0.02 * i, 0.0, 1.0), direction=(0.0, 0.0, -1.0)),
                                 mat), f"s{i}", start="clamp")
    world.compile()
    return world


def sizes_case(args) -> list[dict]:
    rows = []
    for count in args.counts:
        world = hanging(count)
        rows.append({"case": f"hanging {count} x 32", **compare(world, world.step, args.blocks, 4 * args.block)})
    return rows


def line(rec: dict) -> str:
    am = rec["amdahl"]
    return (f"{rec['case']:>18}: serial {rec['serial_ms']:8.3f} ms ({1e3 / rec['serial_ms']:7.1f} steps/s), "
            f"parallel {rec['parallel_ms']:8.3f} ms ({1e3 / rec['parallel_ms']:7.1f} steps/s), "
            f"x{rec['speedup']:.2f} on {rec['chunks']} chunks; kernels {rec['serial_kernels_ms']:.3f} -> "
            f"{rec['parallel_kernels_ms']:.3f} ms (x{rec['kernel_speedup']:.2f}), share {rec['kernel_share']:.0%}; "
            f"Amdahl x{am[2]:.2f} / x{am[4]:.2f} / x{am[8]:.2f} on 2 / 4 / 8 cores, at most "
            f"x{rec['amdahl_limit']:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="hair,pile,sizes")
    ap.add_argument("--blocks", type=int, default=8)
    ap.add_argument("--block", type=int, default=5, help="steps a block (sizes: 4 times as many)")
    ap.add_argument("--strands", type=int, default=1000)
    ap.add_argument("--vertices", type=int, default=32)
    ap.add_argument("--cables", type=int, default=16)
    ap.add_argument("--counts", default="4,16,64,128,256", help="the sizes case's rod counts")
    ap.add_argument("--json", default=None, help="also write the records here (JSON lines)")
    args = ap.parse_args(argv)
    args.counts = [int(c) for c in args.counts.split(",")]
    runs = {"hair": lambda: [hair_case(args)], "pile": lambda: [pile_case(args)], "sizes": lambda: sizes_case(args)}
    print(f"numba {numba.__version__}, {parallel.threads()} threads, MIN_CHUNK_VERTICES "
          f"{parallel.MIN_CHUNK_VERTICES}", flush=True)
    for name in args.cases.split(","):
        for rec in runs[name]():
            print(line(rec), flush=True)
            if args.json:
                with open(args.json, "a") as f:
                    f.write(json.dumps(rec) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
