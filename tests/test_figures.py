"""Still pictures (derods/viz/figures.py): `derods frames` and `derods michell`."""

from __future__ import annotations

import numpy as np
import pytest

from derods.viz import figures, output
from derods.__main__ import main


def colour_pixels(img, rgb, tol=60):
    """Pixels within ``tol`` (per channel) of a colour, to find overlays in a picture."""
    return int(np.sum(np.all(np.abs(img.astype(int) - np.array(rgb)) < tol, axis=-1)))


def read(path):
    return output.mediapy().read_image(path)


@pytest.mark.parametrize("continuity", ["C0", "C1"])
def test_frames_png_shows_rod_and_both_directors(tmp_path, continuity, capsys):
    out = tmp_path / "frames.png"
    assert main(["frames", "--continuity", continuity, "--width", "480", "--height", "320",
                 "--out", str(out)]) == 0
    assert f"{continuity} joins" in capsys.readouterr().out
    img = read(out)
    assert img.shape == (320, 480, 3)
    assert colour_pixels(img, (230, 115, 40)) > 200  # the orange rod
    assert colour_pixels(img, (240, 90, 165)) > 50  # pink normals (u)
    assert colour_pixels(img, (50, 190, 75)) > 20  # green binormals (v)
    assert [p.name for p in tmp_path.iterdir()] == ["frames.png"]


def test_frames_bad_control_points_are_one_line_errors(tmp_path, capsys):
    assert main(["frames", "--control", "0,0,0; 1,1", "--out", str(tmp_path / "f.png")]) == 2
    assert "control points must read" in capsys.readouterr().err
    assert main(["frames", "--control", "0,0,0; 0,0,0; 0,0,0; 0,0,0", "--out", str(tmp_path / "f.png")]) == 2
    assert "degenerate" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_michell_pair_shows_planar_and_buckled_ring(tmp_path):
    info = figures.michell_pair(tmp_path / "m.png", n_edges=40, width=480, height=240)
    planar, buckled = info["out_of_plane"]
    assert planar < 1e-3 and buckled > 0.02
    img = read(tmp_path / "m.png")
    assert img.shape == (240, 480, 3)
    assert colour_pixels(img, (50, 140, 215)) > 100  # the planar ring (blue)
    assert colour_pixels(img, (230, 80, 40)) > 100  # the buckled ring (red)
