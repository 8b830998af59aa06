"""The ``derods bench CASE`` command: run a case by name (:mod:`.cases`, :mod:`.coupling`) and
print its records, one readable line or one JSON object each."""

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
    parts.append(f"{rec['us_per_step']:.0f} us/step" if rec["us_per_step"] else "")
    return " | ".join(p for p in parts if p)


def main(case: str, params: CaseParams, as_json: bool, stream=None) -> int:
    """Run a case and print its records; returns a process exit code."""
    stream = sys.stdout if stream is None else stream
    records = run(case, params)
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
