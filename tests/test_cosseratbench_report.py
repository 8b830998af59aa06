"""benchmarks/cosseratbench_report.py: docs/report/cosseratbench.md from saved result.json
files, whichever environment wrote them (it needs neither the suite nor a solver)."""

from __future__ import annotations

import importlib.util
import json
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _report_module():
    spec = importlib.util.spec_from_file_location("cosseratbench_report", ROOT / "benchmarks" / "cosseratbench_report.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _save(results, experiment, variant, solver, outcome="completed", metrics=None, wall=1.0, settings=None):
    path = results / experiment / variant / solver / "result.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({
        "experiment": experiment, "solver": solver, "outcome": outcome, "n_elements": 20, "n_frames": 101,
        "values": {}, "options": {}, "missing": ["needs cylinders"] if outcome == "unsupported" else [],
        "failure": "blew up" if outcome == "diverged" else None, "diverged_at": 2.5 if outcome == "diverged" else None,
        "wall_time": wall if outcome == "completed" else None, "metrics": metrics or {},
        "observations": {"max_strain": 1e-3, "max_penetration": None, "max_rod_overlap": 0.0},
        "provenance": {"solver_version": f"{solver} 1.0"}, "jobs": 1, "settings": settings or {}}))


def test_the_report_names_the_lowest_error_and_every_outcome(tmp_path):
    report = _report_module()
    results = tmp_path / "results"
    _save(results, "cantilever", "default", "derods", metrics={"tip_deflection_error": 1e-3},
          settings={"mode": "alpha", "time_step": 1e-3})
    _save(results, "cantilever", "default", "mujoco", metrics={"tip_deflection_error": 7e-2})
    _save(results, "cantilever", "resolution=10", "derods", metrics={"tip_deflection_error": 3e-3},
          settings={"mode": "alpha", "time_step": 5e-4})
    _save(results, "twist", "default", "mujoco", outcome="diverged")
    _save(results, "capstan", "default", "dismech", outcome="unsupported")
    out = tmp_path / "report" / "cosseratbench.md"
    report.main(["--results", str(results), "--out", str(out)])
    text = out.read_text()
    summary = next(line for line in text.splitlines() if line.startswith("| cantilever |"))
    assert summary.endswith("| derods |") and "| 0.001 (1.0 s) | 0.07 (1.0 s) |" in summary
    assert "diverged at 2.5 s: blew up" in text and "unsupported: needs cylinders" in text
    assert "mode = alpha, time_step: per scenario" in text  # one rule, many values
    assert [p.name for p in out.parent.iterdir()] == ["cosseratbench.md"]  # no temporary left


def test_no_results_is_an_error_that_says_what_to_run(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        _report_module().main(["--results", str(tmp_path), "--out", str(tmp_path / "x.md")])
    assert exit_info.value.code == 2
    assert "make cosseratbench" in capsys.readouterr().err
