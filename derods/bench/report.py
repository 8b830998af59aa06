"""The comparison report: a Markdown page and error-against-time plots, from records alone.

:func:`report` reads the JSON-lines records that :func:`derods.bench.sweep.sweep`
appends (from any number of environments) and writes ``report.md`` with one
log-log plot of error against wall time per accuracy case (Pareto front
marked), the fastest run to each error level, signed errors by resolution,
the drop table, the stability map and the extreme cases.
"""

from __future__ import annotations

import math
import os
import pathlib
import platform
import time
from collections import defaultdict

from .sweep import ACCURACY_CASES, STABILITY_DT, load

#: Backends whose runs take their own dt per n (PyElastica's largest stable one): their
#: series group over dt.
OWN_DT = ("elastica",)


def _dt_key(r) -> float:
    """A record's dt for grouping: 0 for a backend that picks its own (shown as 'own')."""
    return 0.0 if r["backend"] in OWN_DT else r["dt"]


def _dt_text(dt: float) -> str:
    return "own max stable" if dt == 0.0 else f"{dt:g}"


def _series(records):
    """Records grouped by (case, backend, mode, dt) -> sorted by n."""
    groups = defaultdict(list)
    for r in records:
        if r.get("stable") and r.get("rel_error") is not None and r.get("wall_s"):
            groups[(r["case"], r["backend"], r.get("mode"), _dt_key(r))].append(r)
    return {k: sorted(v, key=lambda r: r["n_edges"]) for k, v in groups.items()}


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (cost, error) that no other point beats in both."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def fastest_to(records, case: str, threshold: float, backend: str | None = None):
    """(backend/mode label, wall [s], n, dt) of the cheapest run (of ``backend``, or any)
    with |error| <= threshold, or None."""
    best = None
    for r in records:
        if r["case"] != case or not r.get("stable") or r.get("rel_error") is None:
            continue
        if backend is not None and r["backend"] != backend:
            continue
        if abs(r["rel_error"]) <= threshold and (best is None or r["wall_s"] < best[1]):
            best = (f"{r['backend']}/{r.get('mode')}", r["wall_s"], r["n_edges"], r["dt"])
    return best


def report(results, out_dir, command: str = "") -> pathlib.Path:
    """Write report.md and one error-vs-wall-time PNG per case into ``out_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    records = load(results)
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    series = _series(records)
    cases = sorted({r["case"] for r in records} & set(ACCURACY_CASES))
    lines = ["# derods against MuJoCo's native rods and PyElastica", ""]
    versions = sorted({(r.get("backend"), r.get("mujoco_version")) for r in records})
    lines += [f"Generated {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} from {len(records)} records "
              f"in `{pathlib.Path(results).name}`" + (f" by `{command}`" if command else "") + ".",
              f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
              "MuJoCo per backend: " + ", ".join(f"{b} {v}" for b, v in versions) + "."]
    if any(r.get("backend") == "cable" for r in records):
        lines.append("The cable records come from the same sweep with `--backends cable` in the MuJoCo 3.17 "
                     "environment; `make report` runs both, appending to one results file.")
    if any(r.get("backend") == "elastica" for r in records):
        lines.append("The elastica records are PyElastica 1.0.0's (`--backends elastica` in `.venv-elastica`, "
                     "`make venv-elastica`): explicit PositionVerlet at 0.9 of its largest stable dt, found by "
                     "search per run (`derods/bench/elastica.py`); cantilever, frequency and oscillation only "
                     "(drop, stability and extreme need MuJoCo's contacts and scenes; michell and twist would need "
                     "its twisted directors set by hand).")
    lines.append("")
    for case in cases:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        pts, labels = [], []
        for (c, backend, mode, dt), recs in sorted(series.items()):
            if c != case:
                continue
            xs = [r["wall_s"] for r in recs]
            ys = [max(abs(r["rel_error"]), 1e-7) for r in recs]
            label = f"{backend}/{mode} dt={_dt_text(dt)}"
            ax.loglog(xs, ys, "o-", label=label)
            for r, x, y in zip(recs, xs, ys):
                ax.annotate(str(r["n_edges"]), (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
                pts.append((x, y))
                labels.append(label)
        for i in pareto(pts):
            ax.loglog(*pts[i], "s", mfc="none", mec="k", ms=11)
        ax.set_xlabel("wall time of the run [s]")
        ax.set_ylabel("|relative error|")
        ax.set_title(f"{case}: error against run time (squares: Pareto front; labels: n)")
        ax.grid(True, which="both", alpha=0.3)
        if pts:
            ax.legend(fontsize=7)
        fig.tight_layout()
        png = out_dir / f"{case}.png"
        fig.savefig(png, dpi=110)
        plt.close(fig)
        lines += [f"## {case}", "", f"![{case}]({png.name})", ""] + _fastest_table(records, case)
        lines += [""] + _error_by_n(series, case)
        bad = [r for r in records if r["case"] == case and not r.get("stable")]
        if bad:
            lines += ["", "Unstable or failed runs: " + "; ".join(
                f"{r['backend']}/{r.get('mode')} n={r['n_edges']} dt={r['dt']:g}" for r in bad)]
        lines.append("")
    lines += _drop_section(records) + _oscillation_section(records) + _hair_section(records) + _targets(records)
    lines += _stability_section(records)
    lines += _extreme_section(records)
    path = out_dir / "report.md"
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)
    return path


def _error_by_n(series, case: str) -> list[str]:
    """Signed relative error [%] per run, backend/mode/dt against n: whether each
    backend converges, or reaches a target by crossing zero."""
    rows = {k[1:]: {r["n_edges"]: r["rel_error"] for r in v} for k, v in series.items() if k[0] == case}
    ns = sorted({n for errs in rows.values() for n in errs})
    if not rows:
        return []
    out = ["Signed error [%] by n:", "", "| backend/mode, dt | " + " | ".join(f"n = {n}" for n in ns) + " |",
           "|---|" + "---|" * len(ns)]
    for (backend, mode, dt), errs in sorted(rows.items()):
        cells = [f"{100 * errs[n]:+.3g}" if n in errs else "" for n in ns]
        out.append(f"| {backend}/{mode}, {_dt_text(dt)} | " + " | ".join(cells) + " |")
    return out


LEVELS = (0.1, 0.01, 0.001)


def _backends(records, case: str) -> list[str]:
    """The backends with records of ``case``, derods first."""
    names = {r["backend"] for r in records if r["case"] == case}
    return sorted(names, key=lambda b: (b != "der", b))


def _fastest_table(records, case: str) -> list[str]:
    """Per error level, each backend's cheapest run to it (wall, mode, n, dt); the fastest
    in bold."""
    backends = _backends(records, case)
    out = ["| target error | " + " | ".join(backends) + " |", "|---|" + "---|" * len(backends)]
    for thr in LEVELS:
        best = {b: fastest_to(records, case, thr, b) for b in backends}
        times = [v[1] for v in best.values() if v is not None]
        cells = []
        for b in backends:
            v = best[b]
            if v is None:
                cells.append("not reached")
                continue
            txt = f"{v[1]:.3g} s ({v[0].split('/', 1)[1]}, n = {v[2]}, dt = {v[3]:.2g})"
            cells.append(f"**{txt}**" if v[1] == min(times) else txt)
        out.append(f"| {100 * thr:g} % | " + " | ".join(cells) + " |")
    return out


def _targets(records) -> list[str]:
    """The comparison's targets, met or not, said plainly."""
    out = ["## Targets", "", "Fastest backend to each error level, per accuracy case (wall time of the cheapest "
           "run that reached it; in brackets the runner-up and how many times slower it was):", "",
           "| case | " + " | ".join(f"{100 * t:g} %" for t in LEVELS) + " |", "|---|" + "---|" * len(LEVELS)]
    for case in sorted({r["case"] for r in records} & set(ACCURACY_CASES)):
        cells = []
        for thr in LEVELS:
            runs = sorted((v[1], b) for b in _backends(records, case)
                          if (v := fastest_to(records, case, thr, b)) is not None)
            if not runs:
                cells.append("none")
                continue
            txt = f"{runs[0][1]} {runs[0][0]:.3g} s"
            if len(runs) > 1:
                txt += f" ({runs[1][1]} x{runs[1][0] / runs[0][0]:.3g})"
            cells.append(txt)
        out.append(f"| {case} | " + " | ".join(cells) + " |")
    out.append("")
    cant = [r for r in records if r["case"] == "cantilever" and r.get("stable") and r.get("rel_error") is not None]
    ours = [r["wall_s"] for r in cant if r["backend"] == "der" and abs(r["rel_error"]) <= 0.01]
    theirs = [r["wall_s"] for r in cant if r["backend"] != "der" and abs(r["rel_error"]) <= 0.01]
    if ours and theirs:
        ratio = min(ours) / min(theirs)
        verdict = "met" if ratio <= 0.5 else "MISSED"
        out.append(f"- Cantilever, 1 % error: derods needs {min(ours):.3f} s, the best native backend "
                   f"{min(theirs):.3f} s: ratio {ratio:.2f} (target <= 0.5): **{verdict}**.")
    elif ours:
        out.append(f"- Cantilever, 1 % error: derods needs {min(ours):.3f} s; no native run in this "
                   "sweep reached 1 % (target met by default).")
    else:
        out.append("- Cantilever, 1 % error: derods did not reach it in this sweep: **MISSED**.")
    stab = [r for r in records if r["case"] == "stability"]
    flex_ok = {(r["young"], r["n_edges"]) for r in stab if r["backend"] == "flex" and r["dt"] == 1e-2 and r["stable"]}
    der_ok = {(r["young"], r["n_edges"]) for r in stab
              if r["backend"] == "der" and r.get("mode") == "implicit" and r["dt"] == 1e-2 and r["stable"]}
    if flex_ok:
        missing = sorted(flex_ok - der_ok)
        verdict = "met" if not missing else "MISSED at (E, n) = " + ", ".join(f"({e:g}, {n})" for e, n in missing)
        out.append(f"- Stable at dt = 1e-2 wherever the native discrete flex is ({len(flex_ok)} (E, n) pairs): "
                   f"**{verdict}**.")
    implicit = {(r["young"], r["n_edges"], r["dt"]) for r in stab
                if r["backend"] == "der" and r.get("mode") == "implicit" and r["stable"]}
    alpha = {(r["young"], r["n_edges"], r["dt"]) for r in stab
             if r["backend"] == "der" and r.get("mode") == "alpha" and r["stable"]}
    if alpha:
        missing = sorted(implicit - alpha)
        verdict = "met" if not missing else "MISSED at (E, n, dt) = " + ", ".join(
            f"({e:g}, {n}, {dt:g})" for e, n, dt in missing)
        out.append(f"- The alpha mode stable wherever the implicit mode is ({len(implicit)} (E, n, dt) "
                   f"triples): **{verdict}**.")
    osc = [r for r in records if r["case"] == "oscillation" and r["backend"] == "der" and r.get("mode") == "alpha"
           and r["dt"] == 1e-2 and r.get("variant", "clamped") == "clamped" and r.get("stable")]
    if osc:
        kept = min(r["measured"] for r in osc)
        worst = max(abs(r["frequency_error"]) for r in osc if r["n_edges"] >= 50) if any(
            r["n_edges"] >= 50 for r in osc) else math.nan
        verdict = "met" if kept >= 0.99 and worst <= 0.01 else "MISSED"
        out.append(f"- The alpha mode keeps >= 0.99 of the cantilever's swing per period at dt = 1e-2 (kept "
                   f"{kept:.4f}), frequency within 1 % at n = 50 (worst {100 * worst:.2f} %): **{verdict}**.")
    if not any(r["backend"] == "cable" for r in records):
        out.append("- The cable backend (MuJoCo 3.17) has no records here: run `make report` with "
                   "`make venv317` done first.")
    out.append("")
    return out


def _drop_section(records) -> list[str]:
    drops = [r for r in records if r["case"] == "drop"]
    if not drops:
        return []
    out = ["## drop", "", "A free rod dropped from 0.5 m (flat, tilted 0.3 rad) on the floor and across a box "
           "edge, 3 s, mass damping 2/s. Penetration after the impact is over (from 0.5 s after first "
           "contact), during impact, and whether the rod came to rest (speed < 1 mm/s).", "",
           "| backend | n | dt | scene | tilt | at rest at [s] | penetration after / during impact [mm] | us/step |",
           "|---|---|---|---|---|---|---|---|"]
    for r in sorted(drops, key=lambda r: (r["backend"], r["n_edges"], r["dt"], r.get("scene", ""), r.get("tilt", 0))):
        if not r.get("stable"):
            out.append(f"| {r['backend']} | {r['n_edges']} | {r['dt']:g} | {r.get('scene')} | {r.get('tilt')} | "
                       f"UNSTABLE | {r.get('note', '')[:60]} | |")
            continue
        rest = f"{r['rest_time']:.2f}" if r.get("at_rest") else "not at rest"
        out.append(f"| {r['backend']} | {r['n_edges']} | {r['dt']:g} | {r['scene']} | {r['tilt']:g} | {rest} | "
                   f"{1000 * r['measured']:.2f} / {1000 * r['impact_penetration']:.1f} | {r['us_per_step']:.0f} |")
    return out + [""]


def _oscillation_section(records) -> list[str]:
    osc = [r for r in records if r["case"] == "oscillation"]
    if not osc:
        return []
    out = ["## oscillation", "", "Numerical damping: an undamped cantilever (clamped: E = 1e9 Pa, L = 1 m, r = 1 cm, "
           "f1 = 2.80 Hz) released straight under gravity, and a free-free rod 2.5 m long (free: f1 = 2.85 Hz) "
           "started in its first mode without gravity; the fraction of its amplitude kept per period over 10 "
           "periods (1 for an exact integrator; backward Euler keeps (1 + (omega h)^2)^(-1 / (2 f1 h))) and the "
           "frequency error against Euler-Bernoulli's first mode. The cable carries the joint damping its "
           "set-up adds (0.01 E I / h, `derods/bench/cable.py`), which dominates its loss at every dt. "
           "der/alpha is `World(mode=\"alpha\")` (generalized-alpha, rho_inf = 0.6: second order, no damping of "
           "resolved modes); elastica runs explicitly at its own largest stable dt.", "",
           "| rod | backend/mode | n | dt | amplitude kept per period | frequency error | us/step |",
           "|---|---|---|---|---|---|---|"]
    for r in sorted(osc, key=lambda r: (r.get("variant", "clamped"), r["backend"], r.get("mode", ""), r["n_edges"],
                                        -r["dt"])):
        label = f"{r.get('variant', 'clamped')} | {r['backend']}/{r.get('mode')}"
        if not r.get("stable") or r.get("measured") is None:
            out.append(f"| {label} | {r['n_edges']} | {r['dt']:g} | {'UNSTABLE' if not r.get('stable') else '-'} | "
                       f"{r.get('note', '')[:120]} | |")
            continue
        out.append(f"| {label} | {r['n_edges']} | {r['dt']:g} | {r['measured']:.4f} | "
                   f"{100 * r['frequency_error']:+.2f} % | {r['us_per_step']:.0f} |")
    return out + [""]


def _hair_section(records) -> list[str]:
    hair = [r for r in records if r["case"] == "hair"]
    if not hair:
        return []
    out = ["## hair", "", "R curled strands x 32 vertices clamped on a shaking mocap head (`derods bench hair`, "
           "`benchmarks/bench_hair.py`), dt = 1e-2 s; penetration into the skull after the impact transients "
           "(from 0.5 s after the head starts to move) and over the whole run, the largest edge strain, and how "
           "far a root left its scalp site.", "",
           "| backend | strands | build (of it MuJoCo's compile) [s] | ms/step (median) | penetration after / all "
           "[mm] | max strain | root drift [m] | note |", "|---|---|---|---|---|---|---|---|"]
    for r in sorted(hair, key=lambda r: (r["strands"], r["backend"])):
        head = f"| {r['backend']} | {r['strands']} | {r['build_s']:.2f} ({r.get('mujoco_compile_s', math.nan):.2f}) |"
        if not r.get("stable"):
            out.append(f"{head} UNSTABLE | | | | {r.get('note', '')[:400]} |")
            continue
        out.append(f"{head} {r['median_us_per_step'] / 1e3:.1f} | {1e3 * r['penetration']:.2f} / "
                   f"{1e3 * r['penetration_max']:.2f} | {r['max_strain']:.1e} | {r['root_drift']:.1e} | "
                   f"{r.get('note', '')[:400]} |")
    return out + [""]


def _label(r) -> str:
    """A record's backend, with derods' mode (der/implicit, der/alpha, flex, ...)."""
    return f"der/{r.get('mode')}" if r["backend"] == "der" else r["backend"]


def _stability_section(records) -> list[str]:
    stab = [r for r in records if r["case"] == "stability"]
    if not stab:
        return []
    backends = sorted({_label(r) for r in stab}, key=lambda b: (not b.startswith("der"), b))
    ns = sorted({r["n_edges"] for r in stab})
    es = sorted({r["young"] for r in stab})
    out = ["## Stability map", "",
           "Largest stable dt [s] of a cantilever (300 steps from rest under gravity, no damping, 1e-6 m/s "
           "random start; unstable = divergence detected, an edge stretched 50 %, or the tip past 1.5 L). "
           "'-' = unstable at every dt tried (" + ", ".join(f"{d:g}" for d in STABILITY_DT) + "); 'n/a' = not run "
           "(the cable's O(n^3) step makes n = 400 too slow for the sample).", "",
           "| E [Pa] | " + " | ".join(f"{b} n={n}" for b in backends for n in ns) + " |",
           "|---|" + "---|" * (len(backends) * len(ns))]
    for e in es:
        cells = []
        for b in backends:
            for n in ns:
                runs = [r for r in stab if _label(r) == b and r["n_edges"] == n and r["young"] == e]
                ok = [r["dt"] for r in runs if r["stable"]]
                cells.append(f"{max(ok):g}" if ok else ("-" if runs else "n/a"))
        out.append(f"| {e:g} | " + " | ".join(cells) + " |")
    return out + [""]


def _extreme_section(records) -> list[str]:
    ext = [r for r in records if r["case"] == "extreme"]
    if not ext:
        return []
    out = ["## Extreme cases", "",
           "soft: E = 1e4 Pa cantilever; steel_wire: E = 2e11 Pa, r = 0.5 mm cantilever; impact: a rod "
           "thrown at the floor at 20 m/s; hairpin: a rod folded back on itself (bend radius 2 r); "
           "edge_ratio: a cantilever with one edge 1000 times shorter; ring_20_turns: a ring twisted 20 "
           "full turns, which writhes (derods with self-contact; the native rings have none: "
           "'penetrated' = it passed through itself). The native cable takes only uniform segments and "
           "sets shapes only when clamped, hence no hairpin or edge_ratio.", "",
           "| case | backend | outcome | detail |", "|---|---|---|---|"]
    for r in sorted(ext, key=lambda r: (r["variant"], r["backend"])):
        out.append(f"| {r['variant']} | {r['backend']} | {r['outcome']} | {r.get('note', '')[:140]} |")
    return out + [""]
