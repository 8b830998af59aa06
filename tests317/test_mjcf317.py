"""The cable models of mjcf/cables/ in MuJoCo 3.17, where the cable plugin runs them as
written: derods (``World(path)``, which reads the composites as rods here too) settles
them where the plugin does (benchmarks/mjcf_cables.py has the full table)."""

from __future__ import annotations

import math
import pathlib
import warnings

import mujoco
import numpy as np
import pytest

from derods import World

MODELS = pathlib.Path(__file__).resolve().parents[1] / "mjcf" / "cables"


def plugin(name: str, seconds: float, ctrl=None) -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = mujoco.MjModel.from_xml_path(str(MODELS / f"{name}.xml"))
    d = mujoco.MjData(m)
    if ctrl is not None:
        d.ctrl[:] = ctrl
    mujoco.mj_step(m, d, int(round(seconds / m.opt.timestep)))
    return m, d


def chain(m, d, prefix: str) -> np.ndarray:
    """The plugin cable's vertices: its bodies' origins and S_last."""
    ids = [m.body(f"{prefix}B_first").id]
    while m.body(ids[-1]).name != f"{prefix}B_last":
        ids.append(int(np.flatnonzero(m.body_parentid == ids[-1])[0]))
    return np.vstack([d.xpos[ids], d.site_xpos[m.site(f"{prefix}S_last").id]])


def test_the_s_curve_on_its_slider_settles_where_the_plugins_does():
    """Within 2 % of the cable's length (measured 0.46 %)."""
    m, d = plugin("s_curve_slider", 3.5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = World(str(MODELS / "s_curve_slider.xml"), dt=1e-2)
    w.step(200)
    gap = np.max(np.linalg.norm(w.positions("cable") - chain(m, d, ""), axis=1))
    assert gap < 0.02 * w.rods[0].length


def test_the_plugin_twists_the_belt_as_derods_and_the_closed_form():
    m, d = plugin("belt_motor", 1.0, ctrl=0.002)
    rel = d.xmat[m.body("beltB_last").id].reshape(3, 3)
    turn = math.atan2(rel[2, 1], rel[1, 1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = World(str(MODELS / "belt_motor.xml"), dt=1e-2)
    rod, = w.rods
    expected = 0.002 * (rod.length - rod.rest_len[-1]) / rod.material.beta
    assert turn == pytest.approx(expected, rel=5e-3)
