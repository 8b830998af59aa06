"""What derods refuses in a model's rods, and how it says so: one line naming the element (its
line in the file) and the fix; exit code 2 from ``derods run``."""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

from derods import World
from derods.validation import InvalidInputError

ROOT = pathlib.Path(__file__).resolve().parents[1]

CABLE = """<mujoco>
  <extension><plugin plugin="mujoco.elasticity.cable"/></extension>
  <worldbody>
    <composite type="cable" prefix="c" curve="{curve}" count="{count}" size="0.5" initial="{initial}">
      <plugin plugin="mujoco.elasticity.cable"><config key="bend" value="{bend}"/><config key="twist" value="4e6"/>
      </plugin>
      <geom type="{geom}" size="0.004"/>
    </composite>
  </worldbody>
  {extra}
</mujoco>"""
GOOD = dict(curve="s 0 0", count="21 1 1", initial="none", bend="1e7", geom="capsule", extra="")


def load(tmp_path, **changes) -> str:
    path = tmp_path / "cable.xml"
    path.write_text(CABLE.format(**{**GOOD, **changes}))
    with pytest.raises(InvalidInputError) as err:
        World(str(path))
    return str(err.value)


def test_the_good_model_loads(tmp_path):
    path = tmp_path / "cable.xml"
    path.write_text(CABLE.format(**GOOD))
    assert World(str(path)).rod_names == ["ccable"]


@pytest.mark.parametrize("change, words", [
    (dict(curve="s tan(s) 0"), ["composite prefix 'c' (cable.xml line 4)", "'tan(s)'", 'write e.g. curve="s 0 0"']),
    (dict(count="21 2 1"), ["composite prefix 'c' (cable.xml line 4)", '"N 1 1"', 'count="41 1 1"']),
    (dict(count="4 1 1"), ["has 4 vertices", "at least 5", "raise count"]),
    (dict(initial="fixed"), ['initial="fixed"', "free, ball, none"]),
    (dict(geom="sphere"), ["geom prefix 'c' (cable.xml line 7)", "capsule, cylinder or box", 'type="capsule"']),
    (dict(bend="abc"), ["plugin prefix 'c' (cable.xml line 5)", 'key="bend" value="abc"', "Young's modulus",
                        '<config key="bend" value="1e7"/>']),
    (dict(bend="-5"), ['key="bend" value="-5"', "> 0 [Pa]"]),
    (dict(extra='<equality><connect body1="cB_3" body2="world" anchor="0 0 0"/></equality>'),
     ["connect (cable.xml line 10)", 'body1="cB_3"', "replaces by a rod", "B_first, B_last, S_first or S_last"]),
    (dict(extra='<contact><pair geom1="cG4" geom2="cG9"/></contact>'), ["pair (cable.xml line 10)", "'cG4'"]),
])
def test_a_bad_attribute_is_one_line_naming_the_element_and_the_fix(tmp_path, change, words):
    text = load(tmp_path, **change)
    assert "\n" not in text
    for w in words:
        assert w in text, text


def test_two_cables_need_two_prefixes(tmp_path):
    path = tmp_path / "twins.xml"
    one = CABLE.format(**GOOD).split("<worldbody>")[1].split("</worldbody>")[0]
    path.write_text(CABLE.format(**GOOD).replace(one, one + one))
    with pytest.raises(InvalidInputError, match=r"composite prefix 'c' \(twins.xml line 10\): has the prefix 'c' of "
                                                r"another cable composite: give each its own prefix"):
        World(str(path))


def test_a_cable_without_stiffness_is_refused(tmp_path):
    path = tmp_path / "floppy.xml"
    path.write_text("""<mujoco><worldbody><composite type="cable" curve="s" count="21 1 1" size="0.5">
        <geom type="capsule" size="0.004"/></composite></worldbody></mujoco>""")
    with pytest.raises(InvalidInputError, match=r"composite \(floppy.xml line 1\): has neither the cable plugin nor "
                                                r"joint stiffness.*mujoco.elasticity.cable"):
        World(str(path))


def test_joint_stiffness_alone_gives_e_i_equal_to_k_l(tmp_path):
    """No plugin: a jointed chain of stiffness k between edges of length l bends with E I = k l."""
    path = tmp_path / "jointed.xml"
    path.write_text("""<mujoco><worldbody><composite type="cable" curve="s" count="21 1 1" size="0.5">
        <joint kind="main" stiffness="0.2"/><geom type="capsule" size="0.004"/></composite></worldbody></mujoco>""")
    rod, = World(str(path)).rods
    assert rod.material.alpha == pytest.approx(0.2 * 0.025, rel=1e-12)
    assert rod.material.beta == pytest.approx(0.2 * 0.025, rel=1e-12)


def test_other_composite_types_and_unknown_attributes_are_named(tmp_path):
    path = tmp_path / "grid.xml"
    path.write_text('<mujoco><worldbody><composite type="grid" count="5 5 1"/></worldbody></mujoco>')
    with pytest.raises(InvalidInputError, match=r'^composite \(grid.xml line 1\): type="grid": derods reads '
                                                r'type="cable" composites only'):
        World(str(path))
    path.write_text(CABLE.format(**GOOD).replace('initial="none"', 'initial="none" spacin="0.1"'))
    with pytest.raises(InvalidInputError, match="unknown attribute spacin"):
        World(str(path))


def test_a_box_section_flexcomp_is_refused_with_the_way_out(tmp_path):
    path = tmp_path / "flex.xml"
    path.write_text("""<mujoco><option integrator="Euler"/><worldbody>
      <flexcomp name="f" type="grid" dim="1" count="11 1 1" spacing="0.05 0.05 0.05">
        <elasticity young="1e7" section="box" sectionsize="0.01 0.002"/></flexcomp></worldbody></mujoco>""")
    with pytest.raises(InvalidInputError, match=r'elasticity \(flex.xml line 3\): section="box".*composite cable '
                                                r'with a box geom'):
        World(str(path), rods_from="flexcomp")


def test_rods_from_is_checked():
    with pytest.raises(InvalidInputError, match="rods_from must be one of"):
        World(str(ROOT / "mjcf" / "cables" / "two_cables.xml"), rods_from="flex")
    with pytest.raises(InvalidInputError, match="rods_from='flexcomp' reads the flexcomps of a scene file"):
        World(None, rods_from="flexcomp")


def test_derods_run_films_a_model_and_refuses_a_bad_one_with_exit_2(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = tmp_path / "belt.mp4"
    ok = subprocess.run([sys.executable, "-m", "derods", "run", str(ROOT / "mjcf" / "cables" / "belt_motor.xml"),
                         "--seconds", "0.2", "--fps", "10", "--width", "160", "--height", "96", "--ctrl",
                         "twist=0.002", "--out", str(out), "--quiet"], capture_output=True, text=True, env=env)
    assert ok.returncode == 0, ok.stderr[-2000:]
    assert "wrote" in ok.stdout and "3 frames" in ok.stdout and out.stat().st_size > 1000
    bad = tmp_path / "bad.xml"
    bad.write_text(CABLE.format(**{**GOOD, "curve": "s wave 0"}))
    run = subprocess.run([sys.executable, "-m", "derods", "run", str(bad), "--out", str(tmp_path / "x.mp4")],
                         capture_output=True, text=True, env=env)
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("derods run: error: composite prefix 'c' (bad.xml line 4)")
    assert not (tmp_path / "x.mp4").exists()
    run = subprocess.run([sys.executable, "-m", "derods", "run", str(ROOT / "mjcf" / "cables" / "belt_motor.xml"),
                          "--ctrl", "spin=1", "--out", str(tmp_path / "x.mp4")], capture_output=True, text=True,
                         env=env)
    assert run.returncode == 2 and "no actuator 'spin'; its actuators: ['twist']" in run.stderr


def test_view_of_a_model_without_a_display_says_so(monkeypatch, capsys):
    from derods.apps.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(ROOT / "mjcf" / "cables" / "belt_motor.xml")]) == 2
    err = capsys.readouterr().err
    assert "needs a display" in err and "derods run" in err
