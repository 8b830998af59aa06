"""This checkout's compiled kernels against another revision's, in one process: the contact
stage (``contact_step``) and the rods' terms (``rods_step``) of bench_world's worlds, each
timed in a compiled loop, the two builds alternating; and whether both give the same bits.

On a shared VM whose speed drifts by a third between runs, two builds timed in one process,
run after run in turn, are the comparison to trust for a change inside the kernels. The other
revision's ``derods/_numba`` is written out of git into a temporary package of its own
(its imports of ``derods``' other modules stay on this checkout's) and compiled beside this
one (an empty numba cache: the first run compiles both, a few minutes). The worlds are
stepped by this checkout; after ``--settle`` steps each kernel runs on the world's own
arrays, ``--loops`` times per timing, ``--repeat`` timings a build.

Worlds (bench_world's cases): ``lying10`` (ten rods of 32 vertices on the floor),
``lying1`` (one), ``box`` and ``floor`` (drop n = 50).

Run: .venv/bin/python benchmarks/bench_kernels_ab.py REV [--worlds lying10,lying1,box,floor]
     [--settle 250] [--loops 300] [--repeat 7]
"""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba as nb
import numpy as np

import derods._numba.contact as contact_now
import derods._numba.implicit as implicit_now
import derods._numba.step as step_now
from bench_world import drop, strands
from derods.sim import contact as stage

ROOT = Path(__file__).resolve().parent.parent
WORLDS = {"lying10": lambda: strands(10, lying=True)[0](), "lying1": lambda: strands(1, lying=True)[0](),
          "box": lambda: drop("box")[0](), "floor": lambda: drop("floor")[0]()}


def kernels_of(rev: str, into: Path):
    """``derods/_numba`` of git revision ``rev`` as the package ``kernels_<rev>`` in ``into``:
    its (contact, implicit, step) modules."""
    name = "kernels_" + re.sub(r"\W", "_", rev)
    pkg = into / name
    pkg.mkdir()
    files = subprocess.run(["git", "ls-tree", "--name-only", rev, "derods/_numba/"], cwd=ROOT, check=True,
                           capture_output=True, text=True).stdout.split()
    for path in files:
        if not path.endswith(".py") or path.endswith("__init__.py"):
            continue
        text = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, check=True, capture_output=True,
                              text=True).stdout
        text = re.sub(r"^from \.\.(\w*) import", lambda m: f"from derods.{m.group(1)} import" if m.group(1)
                      else "from derods import", text, flags=re.M)
        (pkg / Path(path).name).write_text(text)
    (pkg / "__init__.py").write_text(f'"""derods/_numba at {rev}, for benchmarks/bench_kernels_ab.py."""\n')
    sys.path.insert(0, str(into))
    return tuple(importlib.import_module(f"{name}.{m}") for m in ("contact", "implicit", "step"))


def contact_loop(kernels):
    contact = kernels[0]

    @nb.njit
    def loop(k, efc, supported, local_of_dof, dof_off, width, system, a0, a_out, force_out, max_iter, tol):
        s = 0
        for _ in range(k):
            s += contact.contact_step(efc, None, supported, local_of_dof, dof_off, width, system, a0, a_out,
                                      force_out, max_iter, tol)
        return s
    return loop


def rods_loop(kernels):
    step = kernels[2]

    @nb.njit
    def loop(k, rods, ends, frames, x, xmat, place, bands, band_of_rod, out):
        s = 0
        for _ in range(k):
            s += step.rods_step(rods, ends, frames, x, xmat, place, bands, band_of_rod, out)
        return s
    return loop


def timed(loop, args, loops: int) -> float:
    t0 = time.perf_counter()
    loop(loops, *args)
    return (time.perf_counter() - t0) / loops * 1e6


def run(name: str, builds: dict, settle: int, loops: int, repeat: int) -> dict:
    """One world: per build, the contact stage's and the rods' terms' median time [us], and
    whether the builds' results are the same bits."""
    world = WORLDS[name]()
    world.step(settle)
    st, data = world._step, world.data
    c, lay = st.contact, st.layout
    efc, system = c.rows(data), st.system.arrays
    contact_args, rods_args, results = {}, {}, {}
    for key, kernels in builds.items():
        e = kernels[0].Efc(*efc)._replace(force=efc.force.copy())
        y = kernels[1].System(*(a.copy() for a in system))
        a_out, f_out = c.a.copy(), c.force.copy()
        contact_args[key] = (e, stage.SUPPORTED, c.local_of_dof, c.dof_off, stage.WINDOW, y, st.a0.copy(), a_out,
                             f_out, stage.MAX_ITER, stage.TOL)
        frames = st.frames._replace(**{f: getattr(st.frames, f).copy() for f in st.frames._fields})
        terms = st.terms._replace(**{f: getattr(st.terms, f).copy() for f in st.terms._fields})
        bands = st._bands.copy()
        rods_args[key] = (st.rods, st.ends, frames, st.x, st.xmat, lay.place, bands, st._band_of_rod, terms)
        contact_loop(kernels)(1, *contact_args[key])
        rods_loop(kernels)(1, *rods_args[key])
        results[key] = [a_out, f_out, e.force, bands, terms.grad]
    same = all(np.array_equal(p, q) for p, q in zip(*results.values()))
    loops_c = {k: contact_loop(v) for k, v in builds.items()}
    loops_r = {k: rods_loop(v) for k, v in builds.items()}
    t = {k: {"contact": [], "rods": []} for k in builds}
    for r in range(repeat):
        for key in (list(builds) if r % 2 == 0 else list(builds)[::-1]):
            t[key]["contact"].append(timed(loops_c[key], contact_args[key], loops))
            t[key]["rods"].append(timed(loops_r[key], rods_args[key], loops))
    out = {"world": name, "same": same, "rows": int(data.nefc)}
    for key in builds:
        for part in ("contact", "rods"):
            out[f"{part}_{key}"] = float(np.median(t[key][part]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("rev", help="the git revision to compare with (e.g. HEAD~3)")
    ap.add_argument("--worlds", default="lying10,lying1,box,floor")
    ap.add_argument("--settle", type=int, default=250)
    ap.add_argument("--loops", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        builds = {"then": kernels_of(args.rev, Path(tmp)), "now": (contact_now, implicit_now, step_now)}
        print(f"compiled kernels, us per call (median of {args.repeat} timings of {args.loops} calls); "
              f"then: {args.rev}, now: this checkout")
        print(f"{'world':8s} {'rows':>5s} {'contact then':>13s} {'now':>8s} {'ratio':>6s} {'rods then':>10s} "
              f"{'now':>8s} {'ratio':>6s}  same bits")
        for name in args.worlds.split(","):
            r = run(name, builds, args.settle, args.loops, args.repeat)
            print(f"{name:8s} {r['rows']:5d} {r['contact_then']:13.1f} {r['contact_now']:8.1f} "
                  f"{r['contact_now'] / r['contact_then']:6.3f} {r['rods_then']:10.1f} {r['rods_now']:8.1f} "
                  f"{r['rods_now'] / r['rods_then']:6.3f}  {r['same']}")


if __name__ == "__main__":
    main()
