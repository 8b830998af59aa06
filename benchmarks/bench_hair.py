"""Hair at scale: build time and step cost of R strands x 32 vertices on a shaken head,
derods against the same strands as MuJoCo's native flexcomps, same process.

For R = 10, 100, 300, 1000 (``--strands``), derods' hair (:func:`derods.hair.build`:
strands clamped to a mocap head, strand-head contact with a 1 cm speculative margin,
strand-strand contact off, dt = 1e-2 s, shaking for ``--seconds``) and, up to
``--flex-up-to`` strands, the native flexcomp hair (:mod:`derods.bench.hair`) run
alternately, ``--repeat`` times; each figure is the median over runs (a run's step
cost is the median of its steps). Then the exponent p of cost ~ R^p, fitted by least
squares on log-log over R >= 100 (where per-strand work dominates the fixed cost of
the scene) and over all R. The VM is shared: read ratios and exponents, not
milliseconds.

Run: .venv/bin/python benchmarks/bench_hair.py [--strands 10,100,300,1000] [--repeat 1]
     [--seconds 1] [--flex-up-to 300] [--json FILE] [--append-to RESULTS.jsonl]
Targets (issue "hair at scale"): 1000 strands built in <= 30 s and stepped at >= 10
steps/s; exponent <= 1.1 for build and step.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from derods.bench import hair as hair_bench  # noqa: E402


def fit(r, t):
    """Exponent p of t ~ R^p (least squares on logs); nan with fewer than two points."""
    r, t = np.asarray(r, float), np.asarray(t, float)
    return float(np.polyfit(np.log(r), np.log(t), 1)[0]) if len(r) >= 2 else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", default="10,100,300,1000")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--flex-up-to", type=int, default=300)
    ap.add_argument("--flex-budget", type=float, default=240.0,
                    help="wall time [s] after which a flexcomp run stops stepping (default 240)")
    ap.add_argument("--json", default=None, help="also write the records here (JSON lines)")
    ap.add_argument("--append-to", default=None,
                    help="append each record to this results file as it is made (the report's: "
                         "docs/report/results.jsonl), skipping runs it already holds")
    args = ap.parse_args()
    sizes = [int(v) for v in args.strands.split(",")]
    records, done = [], set()
    if args.append_to and os.path.exists(args.append_to):
        # Resumable, like the report's sweep: runs the results file holds are not repeated.
        with open(args.append_to) as f:
            for line in f:
                try:
                    old = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if old.get("case") == "hair" and old.get("vertices") == 32:
                    done.add((old["backend"], old["strands"]))
                    records.append(old)
    for rep in range(args.repeat):
        for r in sizes:
            for backend in ("der", "flex"):
                if (backend == "flex" and r > args.flex_up_to) or (backend, r) in done:
                    continue
                budget = args.flex_budget if backend == "flex" else None
                rec = hair_bench.run(hair_bench.HairCase(strands=r, seconds=args.seconds, backend=backend,
                                                         max_wall_s=budget))
                rec["repeat"] = rep
                records.append(rec)
                print(hair_bench.format_record(rec), flush=True)
                if args.append_to:
                    with open(args.append_to, "a") as f:
                        f.write(json.dumps(rec) + "\n")
    if args.json:
        tmp = args.json + ".part"
        with open(tmp, "w") as f:
            for rec in records:
                f.write(json.dumps(rec) + "\n")
        os.replace(tmp, args.json)

    def med(backend, r, key):
        vals = [x.get(key, np.nan) for x in records if x["backend"] == backend and x["strands"] == r and x["stable"]]
        return float(np.median(vals)) if vals else float("nan")

    print(f"\n{'R':>6} | {'der build s':>11} | {'of it MuJoCo':>12} | {'der ms/step':>11} | {'steps/s':>7} | "
          f"{'flex build s':>12} | {'flex ms/step':>12} | {'flex / der step':>15}")
    for r in sizes:
        db, dm = med("der", r, "build_s"), med("der", r, "mujoco_compile_s")
        ds = med("der", r, "median_us_per_step") / 1e3
        fb, fs = med("flex", r, "build_s"), med("flex", r, "median_us_per_step") / 1e3
        print(f"{r:>6} | {db:>11.2f} | {dm:>12.2f} | {ds:>11.1f} | {1e3 / ds:>7.1f} | {fb:>12.2f} | {fs:>12.1f} | "
              f"{fs / ds:>15.2f}")
    for label, keep in (("R >= 100", [r for r in sizes if r >= 100]), ("all R", sizes)):
        for backend in ("der", "flex"):
            rs = [r for r in keep if not np.isnan(med(backend, r, "build_s"))]
            if len(rs) < 2:
                continue
            pb = fit(rs, [med(backend, r, "build_s") for r in rs])
            ps = fit(rs, [med(backend, r, "median_us_per_step") for r in rs])
            own = fit(rs, [med(backend, r, "build_s") - med(backend, r, "mujoco_compile_s") for r in rs])
            mj = fit(rs, [med(backend, r, "mujoco_compile_s") for r in rs])
            print(f"exponent in R ({label}, {backend}, R = {rs[0]}..{rs[-1]}): build {pb:.2f} (without MuJoCo's "
                  f"compile {own:.2f}, MuJoCo's compile {mj:.2f}), step {ps:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
