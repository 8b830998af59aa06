"""`derods drop`: scenes, headless videos written atomically, and its errors (derods/apps/drop.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import logging
import math
import time

import numpy as np
import pytest

from derods import scenes
from derods.apps import drop
from derods.sim import strain_limit
from derods.viz import output, render
from derods import DivergenceError
from derods.__main__ import main

SMALL = ["--rods", "2", "--n-edges", "12", "--seconds", "0.6", "--fps", "10", "--width", "320",
         "--height", "180", "--dt", "5e-3", "--quiet"]


def rod_pixels(img: np.ndarray) -> int:
    """Pixels of the first rod's orange-red (0.9, 0.3, 0.15): far more red than blue. The
    scenes are grey, white and blue, so nothing else in the picture qualifies."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return int(np.sum((r > 120) & (r - b > 60) & (r - g > 40)))


def test_drop_writes_a_video_of_falling_rods(tmp_path, capsys):
    out = tmp_path / "drop.mp4"
    assert main(["drop", "--scene", "box", "--out", str(out)] + SMALL) == 0
    # --seconds 0.6 at --fps 10 and --dt 5e-3: exactly 0.6 s simulated, frames at 0, 0.1, ..., 0.6 s.
    assert "7 frames, 0.6 s simulated (120 steps" in capsys.readouterr().out
    video = output.mediapy().read_video(out)
    assert video.shape == (7, 180, 320, 3)
    assert video.metadata.fps == pytest.approx(10.0)
    # The rods fall: frames change over time.
    assert np.abs(video[-1].astype(int) - video[0].astype(int)).mean() > 0.5
    assert rod_pixels(video[0]) > 20 and rod_pixels(video[-1]) > 20
    assert [p.name for p in tmp_path.iterdir()] == ["drop.mp4"]  # no temporary left over


def test_drop_steps_in_the_mode_asked_for(tmp_path, capsys):
    out = tmp_path / "drop.mp4"
    assert main(["drop", "--mode", "alpha", "--out", str(out)] + SMALL) == 0
    assert "(120 steps, alpha," in capsys.readouterr().out


@pytest.mark.parametrize("scene", scenes.names())
def test_every_scene_loads_and_frames_its_rods(scene):
    """Each scene compiles with rods in it, and its camera sees the rods where they start."""
    world = drop.build_world(drop.DropParams(scene=scene, rods=2, n_edges=10))
    cam = render.Camera(world.model, 320, 180, "main")
    try:
        assert rod_pixels(cam.render(world.data)) > 10
    finally:
        cam.close()


def test_interrupted_drop_leaves_no_file(tmp_path, monkeypatch):
    from derods.sim import world as world_mod

    calls = {"n": 0}
    original = world_mod.World.step

    def failing_step(self, n=1):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return original(self, n)

    monkeypatch.setattr(world_mod.World, "step", failing_step)
    out = tmp_path / "drop.mp4"
    assert main(["drop", "--out", str(out)] + SMALL) == 130
    assert list(tmp_path.iterdir()) == []


def test_a_video_aborted_before_its_first_frame_is_silent(tmp_path, caplog):
    """A signal can land after the writer opened its file and before the first frame: the
    abort says nothing of the empty video (it is deleted), and leaves nothing behind."""
    out = tmp_path / "x.mp4"
    with pytest.raises(KeyboardInterrupt):
        with output.VideoWriter(out, (64, 64), 10):
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text


@pytest.mark.parametrize("argv,match", [
    (["--scene", "moon"], "unknown scene 'moon'; choose one of"),
    (["--scene", "/nonexistent/scene.xml"], "does not exist"),
    (["--width", "0"], r"width must be a positive integer \[pixels\]"),
    (["--seconds", "-1"], r"seconds must be finite and > 0 \[s\]"),
    (["--young", "0"], r"young must be finite and > 0 \[Pa\]"),
    (["--out", "/nonexistent/folder/x.mp4"], "output folder '/nonexistent/folder' does not exist"),
    (["--out", "/tmp"], r"--out '/tmp' is a folder; give a file name"),
    (["--out", "/tmp/derods_video"], r"--out '/tmp/derods_video' must end in .mp4 \(it has no extension\)"),
    (["--out", "/tmp/x.gif"], r"must end in .mp4 \(got '.gif'\)"),
    (["--out", "/tmp/x.png"], r"must end in .mp4 \(got '.png'\)"),
    (["--still", "/tmp/x.mp4"], r"--still '/tmp/x.mp4' must end in .png"),
    (["--fps", "1000", "--seconds", "0.1"], r"fps 1000 asks for more frames than steps \(dt 0.005 s\): use fps <= 200"),
    (["--dt", "1", "--seconds", "0.6"], r"0.6 s is not a whole number of steps of dt = 1 s"),
    (["--seconds", "0.65"], r"0.65 s at 10 frames/s is 6.5 frames, not a whole number; use seconds = 0.6 or 0.7"),
    (["--dt", "1", "--fps", "1", "--seconds", "4"], r"dt 1 s lets a rod falling from .* m move .* in one step"),
    (["--young", "1e30"], r"young = 1e\+30 Pa is stiffer than any material"),
])
def test_bad_input_is_a_one_line_error(argv, match, tmp_path, capsys):
    args = ["drop", "--out", str(tmp_path / "x.mp4")] + SMALL + argv
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and __import__("re").search(match, err), err
    assert not (tmp_path / "x.mp4").exists()


def test_unreadable_mjcf_is_reported(tmp_path, capsys):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><geom type='nonsense'/></worldbody></mujoco>")
    assert main(["drop", "--scene", str(bad), "--out", str(tmp_path / "x.mp4")] + SMALL) == 2
    assert "cannot read MJCF scene" in capsys.readouterr().err


def test_overlays_draw_frames_and_bending_colours():
    """--overlay frames adds pink and green director arrows; --overlay bend colours the rods
    from blue (straight) towards red where they bend over the box's edges."""
    world = drop.build_world(drop.DropParams(scene="box", rods=2, n_edges=24, dt=5e-3))
    world.step(300)
    cam = render.Camera(world.model, 480, 270, "main")
    try:
        plain = cam.render(world.data)
        framed = cam.render(world.data, drop.overlay_painter(world, "frames"))
        bent = cam.render(world.data, drop.overlay_painter(world, "bend"))
    finally:
        cam.close()

    def near(img, rgb, tol=60):
        return int(np.sum(np.all(np.abs(img.astype(int) - np.array(rgb)) < tol, axis=-1)))

    assert near(framed, (240, 90, 165)) > near(plain, (240, 90, 165)) + 10  # pink arrows
    assert near(bent, (60, 100, 220)) > 50  # straight parts blue
    assert near(bent, (235, 120, 40), tol=50) + near(bent, (230, 60, 30), tol=50) > 5  # bends warm


def test_rings_bezier_and_a_still(tmp_path, capsys):
    """--shape ring drops closed rods; --control sets Bezier points; --still saves the last frame."""
    out, still = tmp_path / "ring.mp4", tmp_path / "ring.png"
    assert main(["drop", "--shape", "ring", "--overlay", "twist", "--still", str(still), "--out", str(out)]
                + SMALL) == 0
    img = output.mediapy().read_image(still)
    assert img.shape == (180, 320, 3)
    world = drop.build_world(drop.DropParams(shape="ring", rods=1, n_edges=20))
    assert world.rods[0].closed
    out2 = tmp_path / "bz.mp4"
    assert main(["drop", "--shape", "bezier", "--control", "0,0,0; 0.2,0.4,0; 0.4,-0.4,0; 0.6,0,0",
                 "--out", str(out2)] + SMALL) == 0
    assert out2.is_file()
    assert main(["drop", "--still", "/nonexistent/x.png", "--out", str(tmp_path / "z.mp4")] + SMALL) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "z.mp4").exists()


def test_a_plain_user_scene_gets_what_its_video_needs(tmp_path, capsys):
    """An MJCF with only a floor (no light, no camera, a small offscreen buffer) films at the
    default size: derods adds a light, a camera framing the rods and a buffer, and says so;
    the video is not dark and shows the rods."""
    scene = tmp_path / "plain.xml"
    scene.write_text('<mujoco><visual><global offwidth="320" offheight="240"/></visual>'
                     '<worldbody><geom type="plane" size="2 2 0.1" rgba="0.6 0.6 0.6 1"/></worldbody></mujoco>')
    out = tmp_path / "plain.mp4"
    small = [a for a in SMALL]
    small[small.index("--width") + 1], small[small.index("--height") + 1] = "480", "270"
    assert main(["drop", "--scene", str(scene), "--out", str(out)] + small) == 0
    err = capsys.readouterr().err
    assert "made it 480x270" in err and "no light" in err and "no camera 'main'" in err
    video = output.mediapy().read_video(out)
    assert video.shape[1:] == (270, 480, 3)
    assert video[-1].mean() > 60  # lit: the floor is grey, not black
    assert rod_pixels(video[0]) > 20


def test_still_must_not_replace_the_video(tmp_path, capsys):
    out = tmp_path / "x.mp4"
    assert main(["drop", "--out", str(out), "--still", str(tmp_path / "x.mp4")] + SMALL) == 2
    assert "must end in .png" in capsys.readouterr().err
    same = tmp_path / "x.png"
    assert main(["drop", "--out", str(same), "--still", str(same)] + SMALL) == 2
    assert list(tmp_path.iterdir()) == []


def test_a_diverged_run_is_one_line_and_leaves_no_video(tmp_path, capsys, monkeypatch):
    """dt = 0.05 s without the implicit step's strain limit: the rods stretch past 50 % on
    impact; the DivergenceError's message (step, rod, fix) is the one line, exit 2, no file."""
    monkeypatch.setattr(strain_limit, "STRAIN_LIMIT", math.inf)
    assert main(["drop", "--out", str(tmp_path / "x.mp4"), "--dt", "0.05", "--fps", "20", "--seconds", "1",
                 "--width", "320", "--height", "180", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "diverged at step" in err and "try a smaller dt" in err, err
    assert list(tmp_path.iterdir()) == []


def test_rods_that_sink_through_the_scene_are_reported(tmp_path, monkeypatch):
    """Past the refusal of absurd steps (dt = 1 s), a run whose contacts do not hold is caught
    while it is filmed: rods metres deep in the floor are an error, not a video."""
    monkeypatch.setattr(drop, "check_step", lambda world: None)
    p = drop.DropParams(dt=1.0, fps=1.0, seconds=4.0, width=160, height=90)
    with pytest.raises(DivergenceError, match="went into the scene: a contact .* deep"):
        drop.drop(p, tmp_path / "x.mp4", progress=False)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("sig,code,word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
def test_a_signal_ends_the_run_with_one_line_and_no_file(tmp_path, sig, code, word):
    """Ctrl-C (SIGINT, to the whole process group as a terminal sends it) or SIGTERM while a
    video is being written: one line, exit 130 / 143, no video and no temporary file."""
    proc = subprocess.Popen([sys.executable, "-m", "derods", "drop", "--out", "x.mp4", "--seconds", "20",
                             "--width", "320", "--height", "180", "--quiet"], cwd=tmp_path, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and not any(p.name.startswith(".x.") for p in tmp_path.iterdir()):
        time.sleep(0.1)  # wait until the video is being written
    time.sleep(1.0)
    os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert err.strip().splitlines() == [f"derods drop: {word}; no partial output was left"], err
    assert list(tmp_path.iterdir()) == []
