"""Quick checks of the PyElastica backend in its own environment (`make test-elastica`,
run by .ci/run): set up as a careful PyElastica user would, it agrees with the closed
forms derods is tested against. Tolerances: its measured errors (below) with room for
the dt search landing one grid step off."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from derods import bench, shapes
from derods.bench import CaseParams, elastica


def _at_stable_dt(**kwargs) -> CaseParams:
    p = CaseParams(backend="elastica", dt=1.0, **kwargs)
    return dataclasses.replace(p, dt=elastica.search_dt(p))


def test_the_dt_search_brackets_the_explicit_limit():
    """The dt found is stable; twice it (well past the 0.9 margin and the 2 % bisection
    bracket) is not. n = 20, E = 1e8: measured 4.6e-5 s (the peer notes: 5.2e-5 damped)."""
    p = _at_stable_dt(n_edges=20)
    x = shapes.cantilever(1.0, 20, start=(0.0, 0.0, 1.0))
    assert 1e-5 < p.dt < 1e-4
    assert elastica._stable(x, p.material, p.dt, 9.81)
    assert not elastica._stable(x, p.material, 2.0 * p.dt, 9.81)


def test_cantilever_sags_as_the_elastica():
    """Started h/2 behind its clamp, n = 20: within 0.5 % of the elastica (measured -0.11 %)."""
    rec, = bench.cantilever(_at_stable_dt(n_edges=20))
    assert rec["stable"], rec["note"]
    assert abs(rec["rel_error"]) < 0.005


def test_oscillation_keeps_its_amplitude():
    """Explicit and symplectic: the undamped swings keep > 0.999 per period at E = 1e9
    (measured 0.99988 clamped, 1.00006 free: the free rod rings with the faster modes its
    start excites, which the turning points' hysteresis ignores), frequencies within 1 %
    clamped (measured +0.15 %) and 2.5 % free (n = 20: lumped end masses)."""
    clamped, free = bench.oscillation(_at_stable_dt(n_edges=20, young=1e9))
    for rec, tol in ((clamped, 0.01), (free, 0.025)):
        assert rec["stable"], rec["note"]
        assert rec["measured"] > 0.999
        assert abs(rec["frequency_error"]) < tol


def test_set_positions_turns_the_directors_with_the_edges():
    """A bent shape set at rest carries no shear: each element's d3 is its tangent."""
    p = _at_stable_dt(n_edges=10)
    sim, x = p.build.cantilever(p, 0.0, 0.0)
    bent = x.copy()
    bent[:, 2] += 0.05 * np.clip(bent[:, 0], 0.0, None) ** 2
    bent[:2] = x[:2]
    sim.set_positions(0, bent)
    t = np.diff(bent, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    np.testing.assert_allclose(sim.rod.director_collection[2].T, t, atol=1e-12)


def test_what_it_cannot_run_says_so():
    with pytest.raises(ValueError, match="not available for backend 'elastica'"):
        bench.run("drop", _at_stable_dt(n_edges=10))
