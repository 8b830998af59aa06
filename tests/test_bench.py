"""Benchmark records (derods/bench/: cases, measures, command) and the `derods bench` command."""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest

from derods import bench
from derods.__main__ import main

FIELDS = {"case", "backend", "mujoco_version", "n_edges", "dt", "mode", "young", "shear", "length",
          "radius", "density", "gravity", "measured", "reference", "rel_error", "stable", "steps",
          "sim_s", "wall_s", "us_per_step", "active_terms"}


def test_bench_cli_prints_one_json_record_per_run(capsys):
    assert main(["bench", "cantilever", "--n-edges", "8", "--young", "1e9", "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    rec = json.loads(lines[0])
    assert FIELDS <= set(rec)
    assert rec["case"] == "cantilever" and rec["n_edges"] == 8 and rec["young"] == 1e9
    assert rec["active_terms"] == ["bend_isotropic", "stretch"]
    assert rec["stable"] and rec["steps"] > 0 and rec["us_per_step"] > 0


def test_explicit_mode_at_a_large_step_is_recorded_unstable():
    rec, = bench.cantilever(bench.CaseParams(n_edges=10, mode="explicit"))
    assert rec["stable"] is False and "diverged at step" in rec["note"]
    assert rec["measured"] is None and rec["rel_error"] is None


@pytest.mark.parametrize("argv,match", [
    (["bench", "cantilever", "--backend", "cable"], r"backend 'cable' needs MuJoCo 3.x .*make venv317"),
    (["bench", "cantilever", "--dt", "0"], r"dt must be finite and > 0 \[s\]"),
    (["bench", "cantilever", "--young", "-1"], r"young must be finite and > 0 \[Pa\]"),
])
def test_bench_bad_input_is_a_one_line_error(argv, match, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert __import__("re").search(match, err)


def test_format_record_of_a_case_without_a_measure():
    """Extreme-case records carry an outcome, not a measure: printed, not a TypeError."""
    rec = {"case": "extreme", "n_edges": 50, "dt": 2e-3, "young": 1e4, "mode": "implicit", "stable": True,
           "measured": None, "reference": None, "rel_error": None, "us_per_step": 120.0,
           "variant": "soft", "outcome": "stable", "note": ""}
    line = bench.format_record(rec)
    assert "soft: stable" in line and "120 us/step" in line


def test_closest_approach_sees_a_ring_pass_through_itself():
    """The extreme ring's self-penetration check: a figure eight crosses itself (distance 0,
    up to the sampling error spacing / 8); a circle's nearest non-neighbouring parts are a
    chord of just over 3 edge lengths apart along it."""
    import math

    import numpy as np

    t = np.linspace(0, 2 * math.pi, 80, endpoint=False)
    eight = np.stack([np.sin(t), np.sin(t) * np.cos(t), 0 * t], axis=1)
    h = np.linalg.norm(np.diff(eight, axis=0), axis=1).max()
    assert bench.measures.closest_approach(eight, h) < h / 8
    circle = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    h = 2 * math.sin(math.pi / 80)
    assert 3 * h * 0.99 < bench.measures.closest_approach(circle, h) < 3.3 * h


@pytest.mark.parametrize("dt,tol", [(1e-2, 0.05), (1e-3, 0.01)])
def test_oscillation_measures_backward_eulers_numerical_damping(dt, tol):
    """The undamped cantilever (n = 20, E = 1e9 Pa, f1 = 2.80 Hz) swinging under gravity:
    the linearly implicit Euler step keeps (1 + (omega h)^2)^(-1/2) of the amplitude per
    step for a mode of angular frequency omega (the amplification matrix of
    v' = v - h omega^2 (x + h v'), x' = x + h v' has determinant 1 / (1 + (omega h)^2)),
    so (1 + (omega h)^2)^(-N/2) per period of N = 1 / (f1 h) steps: 0.578 at dt = 1e-2
    (measured 0.561, the discrete frequency being 1 % low), 0.946 at dt = 1e-3 (0.944).
    Tolerances: 5 % and 1 % of the closed form."""
    rec, free = bench.oscillation(bench.CaseParams(young=1e9, dt=dt))
    f1 = rec["frequency_ref"]
    wh = 2 * math.pi * f1 * dt
    expected = (1 + wh**2) ** (-0.5 / (f1 * dt))
    assert rec["stable"] and rec["measured"] == pytest.approx(expected, rel=tol)
    assert abs(rec["frequency_error"]) < 0.02
    # The free-free rod, 2.5 L long, swings at 1.018 f1: the same damping, to the same
    # tolerance; its frequency within 2.5 % at n = 20 (measured -2.2 % at dt = 1e-2: the
    # lumped end masses of 12.5 cm edges; -0.45 % at n = 50).
    assert free["variant"] == "free" and free["stable"]
    f1 = free["frequency_ref"]
    wh = 2 * math.pi * f1 * dt
    assert free["measured"] == pytest.approx((1 + wh**2) ** (-0.5 / (f1 * dt)), rel=tol)
    assert abs(free["frequency_error"]) < 0.025


def test_swing_amplitudes_of_a_decaying_sine():
    t = np.linspace(0, 10, 2001)
    z = np.exp(-0.1 * t) * np.cos(2 * np.pi * t)  # amplitude kept per period: exp(-0.1)
    turns, amp = bench.swing_amplitudes(z)
    assert len(turns) == 19  # the last extreme, at t = 10 where the record ends, is unconfirmed
    np.testing.assert_allclose(amp[2:] / amp[:-2], math.exp(-0.1), rtol=1e-3)
    # Ripples of a fast mode (1 % of the swing, 37 times its frequency) are not turns.
    rippled = z + 0.01 * np.sin(2 * np.pi * 37.3 * t)
    turns_r, amp_r = bench.swing_amplitudes(rippled)
    assert len(turns_r) == 19
    np.testing.assert_allclose(amp_r[2:] / amp_r[:-2], math.exp(-0.1), rtol=0.05)


def test_report_has_an_oscillation_section(tmp_path):
    from derods.bench import report

    rec, free = bench.oscillation(bench.CaseParams(young=1e9, dt=1e-2))
    results = tmp_path / "r.jsonl"
    results.write_text(json.dumps(rec) + "\n" + json.dumps(free) + "\n")
    text = report.report(results, tmp_path / "report").read_text()
    assert "## oscillation" in text
    assert f"| clamped | der/implicit | 20 | 0.01 | {rec['measured']:.4f} |" in text
    assert f"| free | der/implicit | 20 | 0.01 | {free['measured']:.4f} |" in text


def test_tip_mass_frequency_closed_form():
    """The coupling case's reference: mu = 0 gives the bare cantilever's 1.8751; a heavy
    tip tends to the massless spring 3 alpha / L^3 with mass m + 33/140 of the rod's
    (beta L)^4 -> 3 / (mu + 33/140), within 1e-4 at mu = 1000."""
    from derods.reference import tip_mass_root

    assert tip_mass_root(0.0) == pytest.approx(1.8751040687, abs=1e-9)
    for mu in (10.0, 1000.0):
        assert tip_mass_root(mu) ** 4 == pytest.approx(3.0 / (mu + 33.0 / 140.0), rel=2e-3 if mu == 10 else 1e-4)


def test_bodies_of_any_mass_pinned_to_a_rod_swing_at_the_closed_form():
    """The coupling case at dt = 1e-2 (n = 20, E = 1e7): bodies of 1e-3, 1 and 10 times the
    rod's mass pinned to its tip swing at the tip-mass beam's frequency (measured -0.03 %,
    +0.01 %, +0.03 %; all of 1e-3 .. 1e3 within 0.04 %). Before the implicit coupling of
    derods.sim.holders every one of them diverged within three steps."""
    from derods.bench import coupling as cp

    p = bench.CaseParams(n_edges=20, dt=1e-2, young=1e7)
    old = cp.MASS_RATIOS
    cp.MASS_RATIOS = (1e-3, 1.0, 10.0)
    try:
        records = cp.coupling(p, periods=2.0)
    finally:
        cp.MASS_RATIOS = old
    for rec in records:
        assert rec["stable"], rec["note"]
        assert abs(rec["rel_error"]) < 0.01, rec


def test_only_rods_held_by_bodies_with_dofs_are_coupled():
    """The coupled solve costs nothing where nothing needs it: rods held by the world (or
    by mocap bodies) have no holders; a body with dofs holds, damped by MuJoCo or not."""
    from derods.bench import coupling as cp

    p = bench.CaseParams(n_edges=10, dt=1e-2, young=1e7)
    assert cp.held_world(p, 1.0)._step.holders
    world, _ = p.build.cantilever(p, p.gravity, 0.0)
    world.compile()
    assert not world._step.holders
    assert cp.held_world(p, 1.0, joint_damping=0.1)._step.holders


def test_holders_keep_no_dense_matrix_of_the_whole_model():
    """The coupled solve's memory follows the holders' dofs, not MuJoCo's nv: a dense nv x nv
    mass matrix (kept for every world once) asked 60 GB of the 1000-strand hair. Its mass
    block, a column per dof through mj_mulM, equals the dense matrix's."""
    from derods.bench import coupling as cp

    p = bench.CaseParams(n_edges=10, dt=1e-2, young=1e7)
    world = cp.held_world(p, 1.0)
    holders, m, d = world._step.holders, world._step.model, world._step.data
    assert all(a.size < m.nv ** 2 for a in vars(holders).values() if isinstance(a, np.ndarray))
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    np.testing.assert_allclose(holders._dynamics.mass(m, d, holders.tree), full[np.ix_(holders.tree, holders.tree)], rtol=1e-12)


def test_median_step_counts_a_call_of_n_steps_as_n_steps():
    """A call of 3 steps at 3 us each outweighs one slow step of 1000 us (a kernel loaded
    on first use): the median step is 3 us, where wall / steps would say 252 us."""
    from derods.bench.measures import median_step_us

    assert median_step_us([(1e-3, 1), (3e-6, 3)]) == pytest.approx(3.0)
    assert median_step_us([]) is None


def test_step_clock_times_the_steps_alone(monkeypatch):
    """The clock counts the wrapped simulator's steps only: a fake clock that advances 2 ms
    per simulated step and 50 ms between steps (the case reading the rod) gives exactly
    2000 us per step (no wall-clock time is measured)."""
    from derods.bench import measures
    from derods.bench.measures import StepClock, record

    now = [0.0]
    monkeypatch.setattr(measures.time, "perf_counter", lambda: now[0])

    class Sim:
        n_steps, active_terms = 0, {}

        def step(self, n=1):
            now[0] += 2e-3 * n
            self.n_steps += n

    clock = StepClock(Sim())
    clock.step()
    now[0] += 0.05  # the case reading the rod between steps: not a step's cost
    clock.step(3)
    assert clock.n_steps == 4 and [n for _, n in clock.samples] == [1, 3]
    rec = record("stability", bench.CaseParams(), clock, 1.0, 1.0, True, wall=0.06)
    assert rec["us_per_step"] == pytest.approx(2000.0, rel=1e-9) and rec["wall_s"] == 0.06


def test_bench_takes_the_median_of_repeats_after_an_untimed_run(monkeypatch, capsys):
    from derods.bench import command
    from derods.bench.sweep import without_timing

    calls = []
    real = command.run
    monkeypatch.setattr(command, "run", lambda case, p: calls.append(case) or real(case, p))
    assert main(["bench", "stability", "--n-edges", "8", "--repeats", "2", "--json"]) == 0
    assert len(calls) == 3  # the first run in the process is not counted
    rec = json.loads(capsys.readouterr().out)
    each = rec["us_per_step_repeats"]
    assert len(each) == 2 and rec["us_per_step"] == pytest.approx(np.median(each))
    alone, = real("stability", bench.CaseParams(n_edges=8))
    assert without_timing(rec) == without_timing(json.loads(json.dumps(alone)))
    assert "repeats" not in rec["note"]


def test_repeats_is_not_a_hair_option(capsys):
    assert main(["bench", "hair", "--repeats", "2"]) == 2
    assert "--repeats is not an option of the hair case" in capsys.readouterr().err
