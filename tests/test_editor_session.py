"""The editor's logic without a browser (derods/editor/session.py): every control is a
method, and what the rod does follows from the real World."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from derods.editor.session import Session, Settings


def test_editing_changes_what_the_rod_is_made_of():
    s = Session()
    x0 = s.samples()
    assert x0.shape == (41, 3)
    s.move_point(1, [-0.3, 0.3, 0.6])
    assert not np.allclose(s.samples(), x0)
    s.set_settings(n_edges=20)
    assert s.samples().shape == (21, 3)
    t, u, v = s.bishop_frames()
    assert t.shape == u.shape == v.shape == (20, 3)
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, u), 0.0, atol=1e-12)  # frames are orthonormal
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    arc, kappa, tau = s.curvature_torsion()
    assert arc.shape == kappa.shape == tau.shape == (21,)
    assert kappa.max() > 1.0  # the default wave bends (radius < 1 m somewhere)


def test_start_runs_the_real_world_and_reset_restores_the_curve():
    """The default wave 0.5 m above the floor falls when started; Pause stops time; Reset
    gives back the edited curve."""
    s = Session(settings=Settings(n_edges=20, dt=5e-3))
    drawn = s.samples()
    s.start()
    assert s.advance(0.2) == 40
    assert s.sim_time == pytest.approx(0.2)
    assert s.positions()[:, 2].mean() < drawn[:, 2].mean() - 0.1  # it fell (g t^2 / 2 = 0.196 m)
    assert s.real_time_factor > 0
    s.pause()
    assert s.advance(0.2) == 0 and s.sim_time == pytest.approx(0.2)
    with pytest.raises(RuntimeError, match="reset first"):
        s.move_point(0, [0, 0, 0])
    s.reset()
    assert s.world is None and s.sim_time == 0.0
    np.testing.assert_array_equal(s.positions(), drawn)


def test_a_pull_lifts_the_rod():
    """The rod dropped on the floor, pulled at its middle towards a point 0.2 m above it,
    rises there (measured 0.18 m at n = 40: the spring sags a little under what it lifts)."""
    s = Session(settings=Settings(n_edges=20, dt=5e-3))
    s.start()
    s.step(200)
    mid = s.positions()[10].copy()
    s.pull(10, mid + (0.0, 0.0, 0.2))
    s.step(200)
    assert s.positions()[10, 2] > mid[2] + 0.1
    s.release()
    s.step(100)
    assert s.positions()[10, 2] < mid[2] + 0.05  # let go, it falls back
    with pytest.raises(IndexError):
        s.pull(99, [0, 0, 1])


def test_clamped_ends_with_an_imposed_twist():
    s = Session(settings=Settings(n_edges=20, dt=5e-3, start="clamp", end="clamp", end_twist=3.0))
    s.step(5)
    state = s.world.rod_state("rod")
    assert state.theta[-1] - state.theta[0] == pytest.approx(3.0, abs=1e-9)
    with pytest.raises(ValueError, match="end_twist needs both ends clamped"):
        s.set_settings(end="free")


def test_michell_preset_buckles_past_the_threshold_only():
    """The ring preset: planar at 0.9 of 2 pi sqrt(3) alpha / beta, out of plane at 1.3
    (n = 40, dt = 1e-2; 3 s simulated: the bending time R^2 sqrt(rho A / alpha) is 0.15 s)."""
    out = {}
    for ratio in (0.9, 1.3):
        s = Session(settings=Settings(n_edges=40, dt=1e-2, young=1e7, shear=5e6, radius=0.005))
        s.michell_preset(ratio)
        assert s.critical_twist == pytest.approx(2 * math.pi * math.sqrt(3))  # alpha / beta = E / 2G = 1
        s.step(300)
        z = s.positions()[:, 2]
        out[ratio] = float(np.ptp(z))
    radius = s.curve.length / (2 * math.pi)
    assert out[0.9] < 0.01 * radius < out[1.3]


def test_save_and_load_round_trip(tmp_path):
    s = Session()
    s.set_join(1, "C0")
    s.move_point(4, [0.2, -0.3, 0.5])
    s.set_settings(young=5e6, start="pin")
    path = s.save(tmp_path / "rod.json")
    assert json.loads(path.read_text())["format"] == "derods-edit/1"
    t = Session()
    t.load(path)
    np.testing.assert_array_equal(t.curve.points, s.curve.points)
    assert t.curve.joins == ("C0",) and t.settings == s.settings
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="not a derods edit file"):
        t.load(tmp_path / "bad.json")


def test_bad_settings_name_the_parameter():
    with pytest.raises(ValueError, match="young must be finite and > 0"):
        Settings(young=-1)
    with pytest.raises(ValueError, match="start must be one of"):
        Settings(start="glue")
    with pytest.raises(TypeError):
        Session().set_settings(colour="red")


def test_export_films_the_rod(tmp_path):
    """An MP4 of the rod falling from the edited curve, through the video path."""
    s = Session(settings=Settings(n_edges=12, dt=5e-3))
    info = s.export(tmp_path / "rod.mp4", seconds=0.2, width=320, height=180)
    assert info["frames"] == 7
    assert (tmp_path / "rod.mp4").stat().st_size > 1000
    assert s.world is None  # the session's own state is untouched
