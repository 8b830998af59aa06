"""The ``derods bench CASE`` command: run a case by name (:mod:`.cases`, :mod:`.coupling`) and
print its records, one readable line or one JSON object each.

Timing protocol (:func:`timed_run`): the case runs once unreported (the first run in a
process loads numba's cached kernels and warms MuJoCo's and the CPU's caches: it read
2.3x slow for ``drop``'s first scene), then ``repeats`` times; a record's ``us_per_step``
is the median over the repeats of each run's median step, ``us_per_step_repeats`` the
per-run medians, ``wall_s`` the median run. A sweep (:mod:`.sweep`) runs each job once:
its median step already leaves the first run's slow steps out."""

from __future__ import annotations

import dataclasses
import json
import platform
import sys

import mujoco
import numpy as np

from .cases import cantilever, circle, drop, frequency, michell, oscillation, stability, twist
from .coupling import coupling
from .extreme import extreme
from .params import BACKEND_CASES, CASES, CaseParams

RUNNERS = {"cantilever": cantilever, "frequency": frequency, "drop": drop, "michell": michell,
           "circle": circle, "twist": twist, "stability": stability, "extreme": extreme,
           "oscillation": oscillation, "coupling": coupling}


def run(case: str, params: CaseParams) -> list[dict]:
    """Run one case and return its records."""
    if case not in RUNNERS:
        raise ValueError(f"unknown case {case!r}; cases: {', '.join(CASES)}")
    if case not in BACKEND_CASES[params.backend]:
        hint = ("; a twisted flex ring needs MuJoCo >= 4.0 (per-edge twist joints): pip install -U mujoco"
                if (case, params.backend) == ("michell", "flex") else "")
        raise ValueError(f"case {case!r} is not available for backend {params.backend!r} "
                         f"(it runs {', '.join(BACKEND_CASES[params.backend]) or 'nothing yet'}){hint}")
    return RUNNERS[case](params)


def environment() -> dict:
    """Versions and machine, for reports."""
    import numba
    import scipy

    return {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "numba": numba.__version__, "mujoco": mujoco.__version__, "machine": platform.machine(),
            "processor": platform.processor() or platform.machine()}


def format_record(rec: dict) -> str:
    """One readable line for a record."""
    parts = [f"{rec['case']}"]
    if "scene" in rec:
        parts.append(f"{rec['scene']} tilt {rec['tilt']:g}")
    if "variant" in rec:
        parts.append(rec["variant"] + (f": {rec['outcome']}" if "outcome" in rec else ""))
    if "mass_ratio" in rec:
        parts.append(f"body {rec['mass_ratio']:g} x the rod's mass")
    parts.append(f"n={rec['n_edges']} dt={rec['dt']:g} E={rec['young']:.3g} {rec['mode']}")
    if not rec["stable"]:
        parts.append(f"UNSTABLE: {rec['note']}")
    elif rec["measured"] is None:
        parts.append(rec.get("note", ""))
    else:
        m, r = rec["measured"], rec["reference"]
        err = rec["rel_error"]
        parts.append(f"measured {m:.6g} reference {r:.6g}" + (f" ({100 * err:+.3f} %)" if err is not None else ""))
        if "at_rest" in rec:
            parts.append("at rest" if rec["at_rest"] else "NOT at rest")
    if rec["us_per_step"]:
        each = rec.get("us_per_step_repeats") or []
        parts.append(f"{rec['us_per_step']:.0f} us/step" + (
            f" (median of {len(each)} runs: {', '.join(f'{v:.0f}' for v in each)})" if len(each) > 1 else ""))
    return " | ".join(p for p in parts if p)


def timed_run(case: str, params: CaseParams, repeats: int = 3, warmup: bool = True) -> list[dict]:
    """Run a case ``repeats`` times (after one unreported run if ``warmup``) and return the
    first repeat's records with their timing over all repeats (see the module docstring).
    The runs are deterministic: a record whose other fields differ between repeats says so
    in its note."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats!r}")
    from .sweep import without_timing

    if warmup:
        run(case, params)
    runs = [run(case, params) for _ in range(repeats)]
    out = []
    for recs in zip(*runs):
        rec = dict(recs[0])
        each = [r["us_per_step"] for r in recs]
        rec["us_per_step"] = float(np.median(each)) if None not in each else None
        rec["us_per_step_repeats"] = each
        rec["wall_s"] = float(np.median([r["wall_s"] for r in recs]))
        if any(without_timing(r) != without_timing(recs[0]) for r in recs[1:]):
            rec["note"] = "; ".join(t for t in (rec.get("note"), "the repeats' records differ") if t)
        out.append(rec)
    return out


def main(case: str, params: CaseParams, as_json: bool, stream=None, repeats: int = 3, warmup: bool = True) -> int:
    """Run a case as :func:`timed_run` does and print its records; returns a process exit code."""
    stream = sys.stdout if stream is None else stream
    records = timed_run(case, params, repeats, warmup)
    for rec in records:
        print(json.dumps(rec) if as_json else format_record(rec), file=stream, flush=True)
    return 0


def params_from_args(args) -> CaseParams:
    """CaseParams from parsed command-line options (see derods.__main__)."""
    fields = {f.name for f in dataclasses.fields(CaseParams)}
    p = CaseParams(**{k: v for k, v in vars(args).items() if k in fields and v is not None})
    if p.backend == "elastica" and getattr(args, "dt", None) is None:
        from .elastica import search_dt

        p = dataclasses.replace(p, dt=search_dt(p))
    return p
