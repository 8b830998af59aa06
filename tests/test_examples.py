"""Every example in examples/ runs in its short --test mode, headless, and writes its outputs."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import pytest

from derods.viz import output

ROOT = pathlib.Path(__file__).parents[1]
EXAMPLES = {
    "drop_scenes": [f"drop_{s}.mp4" for s in ("floor", "box", "table_edge", "stairs", "pegs", "halfpipe", "rail")],
    "bezier_frames": ["frames_C1.png", "frames_C0.png"],
    "michell": ["michell.png"],
    "motor_coil": ["motor_coil.mp4"],
    "knot": ["knot.mp4"],
    "hair_turn": ["hair_turn.mp4"],
    "grasp": ["grasp.mp4"],
    "arm_grasp": ["arm_grasp.mp4"],
}


def test_every_example_is_listed():
    assert sorted(p.stem for p in (ROOT / "examples").glob("*.py")) == sorted(EXAMPLES)


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_example_runs_in_test_mode(name, tmp_path):
    script = ROOT / "examples" / f"{name}.py"
    doc = script.read_text()
    assert "Run:" in doc and "Expected:" in doc and "Shows:" in doc  # the docstring says how and what
    result = subprocess.run([sys.executable, str(script), "--test", "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    mediapy = output.mediapy()
    for out in EXAMPLES[name]:
        path = tmp_path / out
        assert path.is_file(), f"{name} did not write {out}"
        if out.endswith(".mp4"):
            assert len(mediapy.read_video(path)) >= 2
        else:
            assert mediapy.read_image(path).ndim == 3
