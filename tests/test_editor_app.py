"""The browser editor's wiring (derods/editor/app.py), driven from Python: a widget's
value reaches the Session, the simulation thread runs the real World, the scene is drawn.
(A real browser drives the same page in the browser tests.)"""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("viser")

from derods.editor.app import EditorApp, colours  # noqa: E402
from derods.editor.session import Session, Settings  # noqa: E402


@pytest.fixture
def app():
    a = EditorApp(Session("box", settings=Settings(n_edges=20, dt=5e-3)), port=0)
    yield a
    a.stop()


def wait_for(condition, seconds: float = 30.0) -> bool:
    """Poll condition() every 50 ms until it holds (True) or ``seconds`` pass (False)."""
    end = time.time() + seconds
    while time.time() < end:
        if condition():
            return True
        time.sleep(0.05)
    return False


def test_listens_on_loopback_only_by_default(app):
    assert app.url.startswith("http://127.0.0.1:")


def test_widgets_reach_the_session(app):
    app.samples.value = 33
    assert wait_for(lambda: app.session.settings.n_edges == 33)
    app.start_end.value = "clamp"
    assert wait_for(lambda: app.session.settings.start == "clamp")
    app.young.value = 5e6
    assert wait_for(lambda: app.session.settings.young == 5e6)
    assert "bending alpha" in app.stiffness.content


def test_a_bad_value_is_shown_not_applied(app):
    app.twist.value = 2.0  # an end twist needs two clamps
    assert wait_for(lambda: "end_twist needs both ends clamped" in app.file_status.content)
    assert app.session.settings.end_twist == 0.0


def test_running_moves_the_rod_in_real_time_or_faster(app):
    """One rod of 20 edges on the box scene: the simulation thread keeps at least real
    time with no browser attached (measured ~30x here)."""
    drawn = app.session.positions().copy()
    with app.lock:
        app.session.start()
    assert wait_for(lambda: app.session.sim_time > 0.5)
    assert app.session.real_time_factor >= 1.0
    assert np.abs(app.session.positions() - drawn).max() > 0.05
    assert app.status.content.startswith("running")
    with app.lock:
        app.session.reset()
        app.redraw()
    assert app.status.content == "editing"


def test_colour_scale_runs_blue_to_red():
    c = colours(np.array([0.0, 0.5, 1.0, 2.0]), 1.0)
    assert c[0, 2] > c[0, 0] and c[2, 0] > c[2, 2] and np.array_equal(c[2], c[3])


def test_the_command_prints_its_url_and_stops_on_ctrl_c(tmp_path):
    """``derods edit --port 0``: one line with the URL on loopback; Ctrl-C (SIGINT) stops it
    with exit 0."""
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "derods", "edit", "--port", "0"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = ""
        end = time.time() + 60
        while time.time() < end and "open http" not in line:
            line = proc.stdout.readline()
        assert "derods edit: open http://127.0.0.1:" in line
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0
    assert "derods edit: stopped" in out
