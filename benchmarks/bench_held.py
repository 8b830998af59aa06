"""Rods held by bodies under gravity and in contact (issue 27): the sweep of derods/bench/held.py.

Runs :func:`derods.bench.held.grid` (the full grid: every scenario x holder x holder mass
1e-3 .. 1e4 kg x pin / clamp x dt 1e-3, 5e-3, 1e-2, the corners E in {1e5, 1e10} Pa x
n in {20, 100}, and the cart scenes on a mocap cart: 410 cases; ``--quick``: 33;
``--mode``: every case in another mode), one :func:`derods.bench.held.run` per case, in
``--workers`` processes; writes one JSON record per line to ``--out`` (atomically: a temp
file, then os.replace) and prints, per scenario x holder, how many cases are ok of how
many, then every failure with its note. It measures: the exit code is 0 whatever it finds.

Run: .venv/bin/python benchmarks/bench_held.py [--quick] [--workers N] [--out results.jsonl]
     [--strain-limit inf] [--mode alpha] [--bending angle] [--scenario span]
"""

from __future__ import annotations

import argparse
import collections
import json
import multiprocessing
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from derods.bench import held  # noqa: E402


def _run(case: held.Case) -> dict:
    try:
        return held.run(case)
    except Exception as err:  # a scene that fails to build is a result too, not a crash of the sweep
        rec = {k: getattr(case, k) for k in ("scenario", "holder", "mass", "end", "dt", "young", "n_edges")}
        rec.update(ok=False, stable=False, values={}, note=f"{type(err).__name__}: {err}", steps=0, wall_s=0.0)
        return rec


def write_atomically(path: str, records: list[dict]) -> None:
    """One JSON record per line into ``path``, via a temp file in its directory and os.replace."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".bench_held.", suffix=".jsonl")
    try:
        with os.fdopen(fd, "w") as f:
            for rec in records:
                f.write(json.dumps(rec) + "\n")
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def table(records: list[dict]) -> str:
    """Per scenario x holder: ok / total (and how many diverged); then the failures."""
    counts = collections.defaultdict(lambda: [0, 0, 0])
    for r in records:
        c = counts[(r["scenario"], r["holder"])]
        c[0] += r["ok"]
        c[1] += 1
        c[2] += not r["stable"]
    lines = [f"{'scenario':8s} {'holder':6s} {'ok':>4s} / total  unstable"]
    for (s, h), (ok, n, bad) in counts.items():
        lines.append(f"{s:8s} {h:6s} {ok:4d} / {n:<5d}  {bad:8d}")
    ok = sum(r["ok"] for r in records)
    lines.append(f"{'all':15s} {ok:4d} / {len(records):<5d}  {sum(not r['stable'] for r in records):8d}")
    fails = [r for r in records if not r["ok"]]
    if fails:
        lines.append("")
        lines.append("failures:")
    for r in fails:
        lines.append(f"  {r['scenario']:5s} {r['holder']:5s} m={r['mass']:<6g} {r['end']:5s} dt={r['dt']:<6g} "
                     f"E={r['young']:<6g} n={r['n_edges']:<3d} {'stable' if r['stable'] else 'UNSTABLE'} "
                     f"step {r['steps']}: {r['note']}")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the quick grid (33 cases)")
    ap.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    ap.add_argument("--out", default="bench_held.jsonl", help="JSON lines written here")
    ap.add_argument("--strain-limit", type=float, default=None,
                    help="World's strain limit for every case (default: World's own; inf turns it off, to probe)")
    ap.add_argument("--mode", default="auto", choices=("auto", "implicit", "alpha", "projection"),
                    help="World's mode for every case (default auto: implicit here)")
    ap.add_argument("--bending", default="tan", choices=("tan", "angle"),
                    help="the rods' curvature measure for every case (default Bergou's tan)")
    ap.add_argument("--speculative", action="store_true",
                    help="contact margins sized by each rod's speed every step (ContactParams(speculative=True))")
    ap.add_argument("--scenario", default=None, help="only this scenario (default: all)")
    args = ap.parse_args()
    from tqdm import tqdm

    fields = {} if args.strain_limit is None else {"strain_limit": args.strain_limit}
    if args.mode != "auto":
        fields["mode"] = args.mode
    if args.bending != "tan":
        fields["bending"] = args.bending
    if args.speculative:
        fields["speculative"] = True
    cases = [c for c in held.grid(quick=args.quick, **fields) if args.scenario in (None, c.scenario)]
    t0 = time.perf_counter()
    with tqdm(total=len(cases), desc="held rods", unit="case") as bar:
        if args.workers > 1:
            with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
                records = []
                for rec in pool.imap(_run, cases, chunksize=1):
                    records.append(rec)
                    bar.update()
        else:
            records = []
            for case in cases:
                records.append(_run(case))
                bar.update()
    write_atomically(args.out, records)
    print(table(records))
    print(f"\n{len(records)} cases in {time.perf_counter() - t0:.0f} s ({args.workers} workers; "
          f"{sum(r['wall_s'] for r in records):.0f} s of runs); records in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
