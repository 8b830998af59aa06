"""Write docs/report/cosseratbench.md from the results of cosseratbench runs.

cosseratbench (an independent rope and rod benchmark suite, on the package registry)
saves one ``result.json`` per run under ``RESULTS/EXPERIMENT/VARIANT/SOLVER/``: the
suite's own metrics, its observations (strain, penetration, overlap), the wall time
and the numerical settings each adapter chose. This script reads them, whatever
environment ran each solver (derods and MuJoCo 4 in ``.venv``, MuJoCo's cable in
``.venv317``, PyElastica in ``.venv-elastica``), and writes one Markdown section: a
summary of each validation's error per solver at the default resolution, then every
run. It needs neither the suite nor any solver installed.

Usage: ``python benchmarks/cosseratbench_report.py [--results results/cosseratbench]
[--out docs/report/cosseratbench.md]``; ``make cosseratbench`` runs the suite in each
environment and then this. The file is written to a temporary name and moved into
place, so an interrupted run leaves the old report whole.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The metric that scores each validation against its reference (the suite's names), and
#: what it is; experiments without a reference report what they measure.
HEADLINE = {
    "cantilever": ("tip_deflection_error", "tip deflection vs Euler-Bernoulli, relative"),
    "catenary": ("shape_error", "distance to the elastic catenary / L"),
    "crossing": ("lift_error", "lift of the upper rope vs the elastica, relative"),
    "pendulum": ("period_error", "period vs linear vibration theory, relative"),
    "twist": ("critical_twist_error", "critical twist vs Greenhill, relative"),
}
EXPLORATIONS = {
    "capstan": ("slide", "how far the rope moved [m]; at the default overhang (0.8 of the holding one) it should hold"),
    "pile": ("pile_height", "pile height [diameters]; no reference"),
}
SOLVER_ORDER = ("derods", "mujoco", "pyelastica", "dismech")
OBSERVED = ("max_strain", "max_penetration", "max_rod_overlap")


def load(results: Path) -> list[dict]:
    runs = []
    for path in sorted(results.glob("*/*/*/result.json")):
        summary = json.loads(path.read_text())
        summary["variant"] = path.parent.parent.name
        runs.append(summary)
    return runs


def _order(solver: str) -> tuple:
    return (SOLVER_ORDER.index(solver) if solver in SOLVER_ORDER else len(SOLVER_ORDER), solver)


def _num(value, digits: int = 3) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) >= 1e-3 or value == 0 else f"{value:.{digits - 1}e}"
    return str(value)


def _outcome(run: dict) -> str:
    if run["outcome"] == "unsupported":
        return "unsupported: " + "; ".join(run["missing"])
    if run["outcome"] == "diverged":
        at = f" at {run['diverged_at']:.3g} s" if run.get("diverged_at") is not None else ""
        return f"diverged{at}: {run['failure']}"
    return "completed"


def summary_table(runs: list[dict]) -> list[str]:
    solvers = sorted({r["solver"] for r in runs}, key=_order)
    lines = ["| experiment | measure | " + " | ".join(solvers) + " | lowest |",
             "|---|---|" + "---|" * len(solvers) + "---|"]
    for experiment, (metric, what) in {**HEADLINE, **EXPLORATIONS}.items():
        cells, scores = [], {}
        for solver in solvers:
            found = [r for r in runs if r["experiment"] == experiment and r["solver"] == solver
                     and r["variant"] == "default"]
            if not found:
                cells.append("not run")
                continue
            run = found[0]
            if run["outcome"] != "completed":
                cells.append(run["outcome"])
                continue
            value = run["metrics"].get(metric)
            cells.append(f"{_num(value)} ({run['wall_time']:.1f} s)")
            if value is not None:
                scores[solver] = abs(value)
        lowest = min(scores, key=scores.get) if experiment in HEADLINE and scores else ""
        if experiment not in HEADLINE:
            lowest = "(no reference)"
        lines.append(f"| {experiment} | {metric}: {what} | " + " | ".join(cells) + f" | {lowest} |")
    return lines


def experiment_tables(runs: list[dict]) -> list[str]:
    by_experiment = defaultdict(list)
    for run in runs:
        by_experiment[run["experiment"]].append(run)
    lines = []
    for experiment in sorted(by_experiment):
        group = sorted(by_experiment[experiment],
                       key=lambda r: (r["variant"] != "default", r["n_elements"], _order(r["solver"])))
        metrics = sorted({m for r in group for m in r["metrics"]})
        lines += ["", f"### {experiment}", "",
                  "| variant | solver | n | outcome | " + " | ".join(metrics) + " | "
                  + " | ".join(OBSERVED) + " | wall [s] | time step [s] |",
                  "|---|---|---|---|" + "---|" * (len(metrics) + len(OBSERVED) + 2)]
        for run in group:
            settings = run.get("settings") or {}
            step = settings.get("time_step")
            wall = run.get("wall_time")
            lines.append(
                f"| {run['variant']} | {run['solver']} | {run['n_elements']} | {_outcome(run)} | "
                + " | ".join(_num(run["metrics"].get(m)) for m in metrics) + " | "
                + " | ".join(_num(run["observations"].get(o)) for o in OBSERVED) + " | "
                + f"{_num(wall)} | {_num(step)} |")
    return lines


def settings_lines(runs: list[dict]) -> list[str]:
    """Each solver's version and settings: one value where every run used it, "per
    scenario" where the adapter's rule gave different values (time steps, damping)."""
    lines = []
    for solver in sorted({r["solver"] for r in runs}, key=_order):
        mine = [r for r in runs if r["solver"] == solver]
        versions = sorted({str(r["provenance"].get("solver_version")) for r in mine})
        lines.append(f"- **{solver}** ({', '.join(versions)})")
        found = [r["settings"] for r in mine if r.get("settings")]
        if not found:
            continue
        keys = list(dict.fromkeys(k for settings in found for k in settings))
        shown = []
        for key in keys:
            values = {json.dumps(settings.get(key)) for settings in found}
            shown.append(f"{key} = {found[0].get(key)}" if len(values) == 1 else f"{key}: per scenario")
        lines.append("  - " + ", ".join(shown))
    return lines


def render(runs: list[dict], results: Path, note: str = "") -> str:
    jobs = sorted({r.get("jobs", 1) for r in runs})
    lines = [
        "## cosseratbench: derods beside MuJoCo's cable, PyElastica and DisMech",
        "",
        "[cosseratbench](https://pypi.org/project/cosseratbench/) 0.3.0 is a rope and rod benchmark",
        "suite written by others: seven experiments, each a physical scenario with the suite's own",
        "metrics, and one adapter per solver that picks its numerics once. derods takes part through",
        "its adapter `derods/bench/cosseratbench.py` (entry point `derods`). Every run below was made",
        "on the same machine in one session by `make cosseratbench` (derods in `.venv`, MuJoCo 4;",
        "MuJoCo's cable adapter in `.venv317`, MuJoCo 3.17; PyElastica's in `.venv-elastica`), one run",
        f"at a time (runs at once: {', '.join(map(str, jobs))}). Wall times are the suite's: one run after",
        "a warm-up, on a shared 2-core VM. DisMech's adapter needs dismech-python, which is not on the",
        "package registry, so it is not run here.",
        *(["", note] if note else []),
        "",
        "### Summary at each experiment's default resolution",
        "",
        *summary_table(runs),
        "",
        "### Solvers and their settings",
        "",
        *settings_lines(runs),
        "",
        "### Every run",
        *experiment_tables(runs),
        "",
        f"_Source: `{results.relative_to(ROOT) if results.is_relative_to(ROOT) else results}`, "
        f"{len(runs)} runs; regenerate with `make cosseratbench`._",
        "",
    ]
    return "\n".join(lines)


def write_atomically(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=ROOT / "results" / "cosseratbench")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "report" / "cosseratbench.md")
    parser.add_argument("--note", default="", help="a paragraph on how this session's runs were made, if not as above")
    args = parser.parse_args(argv)
    runs = load(args.results)
    if not runs:
        parser.exit(2, f"no cosseratbench results under {args.results}; run `make cosseratbench`\n")
    write_atomically(args.out, render(runs, args.results.resolve(), args.note))
    print(f"wrote {args.out} ({len(runs)} runs)")


if __name__ == "__main__":
    main()
