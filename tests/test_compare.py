"""Backends, sweeps and the report (derods/bench/native.py, derods/bench/sweep.py, derods/bench/report.py)."""

from __future__ import annotations

import concurrent.futures

import numpy as np
import pytest

from derods import bench
from derods.bench import native, report, sweep
from derods.bench import CaseParams
from derods import DivergenceError


@pytest.mark.parametrize("young", [1e6, 1e8, 1e10])
def test_same_rod_same_cantilever_in_every_backend(young):
    """The parameter mapping holds: derods and the native flexcomp give the same static tip
    drop up to their discretization errors. The native clamp holds a whole edge, which
    costs it about 1.65 / n (the baselines' measurement); at n = 50 the two agree to 4 %
    and each is within 4 % of the elastica."""
    recs = {b: bench.cantilever(CaseParams(n_edges=50, young=young, backend=b))[0] for b in ("der", "flex")}
    for rec in recs.values():
        assert rec["stable"] and abs(rec["rel_error"]) < 0.04
    assert abs(recs["flex"]["measured"] / recs["der"]["measured"] - 1) < 0.04
    assert abs(recs["der"]["rel_error"]) < abs(recs["flex"]["rel_error"])


def test_flex_poisson_mapping():
    assert native.poisson_for(1e8, 1e8 / 2.6) == pytest.approx((0.3, False))
    nu, clipped = native.poisson_for(1e8, 1e8 / 3.0)  # G = E/3 means nu = 0.5, outside [0, 0.5)
    assert clipped and nu < 0.5


def test_native_divergence_is_reported():
    x = np.stack([np.linspace(0, 1, 11), np.zeros(11), np.ones(11)], axis=1)
    rod, _ = native.flex_rod(x, CaseParams(n_edges=10), pinned=(0, 1))
    rod.data.qvel[rod.dofs()[-1]] = 1e6
    with pytest.raises(DivergenceError, match="native flex' diverged at step 1.*vertex speed"):
        rod.step()


def test_sweep_appends_resumes_and_reports(tmp_path):
    results = tmp_path / "r.jsonl"
    jobs = sweep.plan(["cantilever", "twist"], ["der", "flex"], [8, 12], [1e-2], young=1e9)
    # twist runs on derods only: 2 cantilever x 2 backends + 2 twist runs
    assert len(jobs) == 6
    assert sweep.sweep(jobs[:3], results, progress=False) == 3
    with open(results, "a") as f:
        f.write('{"case": "torn')  # a crash in the middle of a line
    with concurrent.futures.ThreadPoolExecutor(2) as ex:
        assert sweep.sweep(jobs, results, ex, progress=False) == 3  # only the missing ones
    assert sweep.sweep(jobs, results, progress=False) == 0
    records = sweep.load(results)
    assert len(records) == 6 and all(r["stable"] for r in records)
    path = report.report(results, tmp_path / "report", command="test")
    text = path.read_text()
    assert "## cantilever" in text and "cantilever.png" in text and "| 1 % |" in text
    assert (tmp_path / "report" / "cantilever.png").stat().st_size > 1000


def test_pareto_front():
    pts = [(1.0, 0.1), (2.0, 0.05), (1.5, 0.2), (3.0, 0.01), (2.5, 0.06)]
    assert report.pareto(pts) == [0, 1, 3]


def test_unknown_backend_case_is_an_error(capsys):
    from derods.__main__ import main

    assert main(["bench", "twist", "--backend", "flex"]) == 2
    assert "not available for backend 'flex'" in capsys.readouterr().err
    assert main(["bench", "cantilever", "--backend", "cable"]) == 2
    assert "cable" in capsys.readouterr().err


@pytest.mark.parametrize("backend", ["der", "flex"])
def test_stability_case(backend):
    """Stable at dt = 1e-2 for E = 1e8 in both backends; derods' explicit mode is not."""
    rec, = bench.stability(CaseParams(n_edges=10, backend=backend))
    assert rec["stable"] and rec["measured"] == 1.0
    if backend == "der":
        rec, = bench.stability(CaseParams(n_edges=10, mode="explicit"))
        assert not rec["stable"] and "diverged" in rec["note"]


def test_extreme_cases_record_what_happened():
    """At n = 16, dt = 2e-3 derods survives the soft rod, the steel wire, the 20 m/s impact
    (deepest transient penetration measured 81 mm), the hairpin and the 1000:1 edges; the
    ring twisted 20 turns is too coarse at 16 edges (2.5 turns of twist per edge) and its
    divergence is recorded with the step and the fix (at n = 50, the report's run, it is
    stable and its self-contact keeps it 12.6 mm from itself)."""
    recs = {r["variant"]: r for r in bench.extreme(CaseParams(n_edges=16, dt=2e-3))}
    assert list(recs) == ["soft", "steel_wire", "impact", "hairpin", "edge_ratio", "ring_20_turns"]
    for variant in ("soft", "steel_wire", "impact", "hairpin", "edge_ratio"):
        assert recs[variant]["outcome"] == "stable", recs[variant]["note"]
    impact = float(recs["impact"]["note"].split("impact ")[1].split(" mm")[0])
    assert 10.0 < impact < 150.0  # deeper than the radius transiently, never through the floor
    ring = recs["ring_20_turns"]
    assert ring["outcome"] == "diverged" and "diverged at step" in ring["note"] and "try a smaller dt" in ring["note"]


def test_backend_missing_from_this_mujoco_is_skipped_with_a_message(capsys):
    jobs = sweep.plan(["cantilever"], ["der", "cable"], [8], [1e-2])
    assert [j.params.backend for j in jobs] == ["der"]
    err = capsys.readouterr().err
    assert "skipping backend 'cable'" in err and "make venv317" in err


def test_pyelastica_outside_its_environment_is_skipped_with_a_message(capsys):
    """PyElastica lives in .venv-elastica only (tests_elastica/ checks it there)."""
    jobs = sweep.plan(["oscillation"], ["der", "elastica"], [8], [1e-2])
    assert [j.params.backend for j in jobs] == ["der"]
    err = capsys.readouterr().err
    assert "skipping backend 'elastica'" in err and "make venv-elastica" in err


def test_the_report_names_the_fastest_backend_per_level(tmp_path):
    """Four backends' records: per case and error level the cheapest run of each, the
    fastest in bold, and the targets section's winner with the runner-up's ratio."""
    import json

    recs = []
    for backend, wall, err in (("der", 0.1, 0.005), ("flex", 0.5, 0.02), ("cable", 2.0, 0.0005),
                               ("elastica", 1.0, 0.0008)):
        recs.append({"case": "cantilever", "backend": backend, "mode": "m", "n_edges": 20,
                     "dt": 1e-5 if backend == "elastica" else 1e-2, "young": 1e8, "length": 1.0, "radius": 0.01,
                     "density": 1000.0, "stable": True, "rel_error": err, "wall_s": wall, "measured": 1.0})
    results = tmp_path / "r.jsonl"
    results.write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    text = report.report(results, tmp_path).read_text()
    assert "| target error | der | cable | elastica | flex |" in text
    assert "| 1 % | **0.1 s (m, n = 20, dt = 0.01)** |" in text
    assert "| cantilever | der 0.1 s (flex x5) | der 0.1 s (elastica x10) | elastica 1 s (cable x2) |" in text


def test_unknown_case_or_backend_is_refused_with_the_choices(capsys):
    from derods.__main__ import main

    assert main(["compare", "--cases", "bogus", "--results", "/tmp/never.jsonl"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("derods compare: error: unknown case 'bogus'; choose from cantilever")
    assert main(["compare", "--backends", "der,abaqus", "--results", "/tmp/never.jsonl"]) == 2
    assert "unknown backend 'abaqus'" in capsys.readouterr().err
