"""Packaging: the public names, the package list, and a wheel that runs the main job
outside the repository."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_public_names_and_no_side_effect_at_import():
    """``from derods import World, ContactParams, DivergenceError`` works, and importing
    derods sets no GL backend (rendering picks it when first used)."""
    code = ("import os; before = dict(os.environ); import derods; "
            "from derods import World, ContactParams, DivergenceError, MODES; "
            "assert World.__name__ == 'World' and 'implicit' in MODES; "
            "assert {k: v for k, v in os.environ.items() if before.get(k) != v} == {}, 'environment changed'")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, cwd=ROOT)


def test_every_subpackage_is_listed_in_pyproject():
    """pyproject.toml lists the packages by hand (to map mjcf/ into derods.mjcf): a new
    subpackage must be added there or the wheel would miss it."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "derods").rglob("__init__.py")}
    assert found | {"derods.mjcf"} == listed


@pytest.mark.skipif(not (os.environ.get("CI") or os.environ.get("DERODS_TEST_WHEEL")),
                    reason="builds a wheel and a fresh venv from the package registry (minutes); runs in CI "
                           "(CI=true) or with DERODS_TEST_WHEEL=1")
def test_wheel_installed_outside_the_repository_runs_the_main_job(tmp_path):
    """pip wheel . ; a fresh venv outside the repository; pip install the wheel; from an
    unrelated folder, ``derods drop --seconds 0.5`` writes its video (the scenes ship
    inside the wheel as derods.mjcf)."""
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), str(ROOT)],
                   check=True)
    wheel, = dist.glob("derods-*.whl")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "--quiet", "--progress-bar", "off", str(wheel)], check=True)
    work = tmp_path / "elsewhere"
    work.mkdir()
    run = subprocess.run([str(venv / "bin" / "derods"), "drop", "--seconds", "0.5", "--out", "drop.mp4", "--width",
                          "320", "--height", "180", "--quiet"], cwd=work, capture_output=True, text=True,
                         env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert run.returncode == 0, run.stderr[-2000:]
    assert "16 frames, 0.5 s simulated" in run.stdout
    assert (work / "drop.mp4").stat().st_size > 1000
    assert sorted(p.name for p in work.iterdir()) == ["drop.mp4"]
