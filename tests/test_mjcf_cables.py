"""MuJoCo 3.x cable composites (and 1D flexcomps) read from MJCF as derods rods (derods/io)."""

from __future__ import annotations

import math
import pathlib
import warnings

import mujoco
import numpy as np
import pytest

from derods import World
from derods.io import cable_geometry as geo
from derods.io import mjcf_load

MODELS = pathlib.Path(__file__).resolve().parents[1] / "mjcf" / "cables"
ALL = sorted(p.stem for p in MODELS.glob("*.xml"))


def world(name: str, **kw) -> World:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return World(str(MODELS / f"{name}.xml"), rods_from="flexcomp", **kw)


def world_of(tmp_path, text: str, **kw) -> World:
    """The World of an MJCF model written here as ``text`` (its scene warnings silenced), compiled."""
    path = tmp_path / "model.xml"
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = World(str(path), **kw)
    w.compile()
    return w


@pytest.mark.parametrize("curve, count, size, quat, offset, first, last", [
    # MuJoCo 3.17's body quaternions (xquat) of the first and last bodies of these composites.
    (("cos(s)", "sin(s)", "s"), 30, [1, 0.1, 6], [1, 0, 0, 0], [0.1, 0.2, 0.3],
     [0.5480491679481178, 0.2432341640424916, -0.0800682203086946, 0.7962840768535588],
     [-0.40219210114705733, 0.6918964861874622, 0.5995781714193451, -0.005175184421134232]),
    (("0", "0", "s"), 8, [1, 0, 0], [0, 1, 0, 0], [0, 0, 0],  # straight: MuJoCo's degenerate frames
     [0.0, -0.7071067811865475, 0.0, 0.7071067811865475], [0.0, -0.7071067811865476, 0.0, 0.7071067811865476]),
])
def test_vertices_and_body_frames_are_mujoco_3_17s(curve, count, size, quat, offset, first, last):
    """The composite's vertices and its first and last bodies' frames as MuJoCo 3.17 builds them
    (measured there: body positions 1e-7 apart, float storage); the frames' x axes run along
    the edges."""
    x = geo.curve_vertices(curve, count, size, quat) + offset
    q = geo.body_frames(x)
    for mine, theirs in ((q[0], first), (q[-1], last)):
        assert min(np.abs(mine - theirs).max(), np.abs(mine + theirs).max()) < 1e-6
    t = np.diff(x, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    axes = np.array([geo.quat_to_mat(qi)[:, 0] for qi in q])
    np.testing.assert_allclose(axes, t, atol=1e-9)


def test_a_vertex_list_cable_is_placed_as_mujoco_places_it():
    x = np.array([0, 0, 0, 0.2, 0, 0, 0.3, 0.1, 0, 0.3, 0.2, 0.1, 0.35, 0.25, 0.3]).reshape(-1, 3)
    q = geo.body_frames(x)
    np.testing.assert_allclose(q[0], [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(q[-1], [0.704365926467416, 0.34888353794408744, -0.47086585632760797,
                                       0.4005424620788448], atol=1e-6)


def test_a_box_section_has_the_boxs_stiffnesses_and_mass():
    """The belt's box (half sizes 1 cm x 1 mm) becomes an ellipse with the same E I1, E I2,
    MuJoCo's G J of the rectangle, and the mass per length its geoms weighed."""
    w = world("belt_motor")
    rod, = w.rods
    h, w_ = 0.001, 0.01  # the thinner half size is the first director's
    mat = rod.material
    np.testing.assert_allclose(mat.bend_stiffness, (1e8 * (2 * w_) ** 3 * 2 * h / 12, 1e8 * (2 * h) ** 3 * 2 * w_ / 12),
                               rtol=1e-12)
    assert mat.beta == pytest.approx(4e7 * geo.box_torsion(h, w_), rel=1e-12)
    assert mat.line_density == pytest.approx(1100 * 4 * h * w_, rel=1e-12)
    assert mat.radius < mat.radius2


@pytest.mark.parametrize("size, plugin_sag", [("0 0.01 0.001", 0.21892364191658314),
                                              ("0 0.001 0.01", 0.002426222041094661)])
def test_a_box_belt_sags_as_the_plugins_flat_or_on_edge(tmp_path, size, plugin_sag):
    """The belt under gravity, its motor and key taken off, lying flat (2 cm wide across y:
    soft) and on edge (stiff): the tip sags as MuJoCo 3.17's plugin made it (its numbers, at
    t = 4 s) within 2 % of the length, and on edge as q L'^4 / (8 E I) within 1 % (measured
    0.22 vs 0.22 m and -0.07 %). A section turned by 90 degrees sags 90 times more or less."""
    import re

    text = (MODELS / "belt_motor.xml").read_text()
    text = re.sub(r"<actuator>.*?</actuator>|<keyframe>.*?</keyframe>", "", text, flags=re.S)
    text = text.replace('gravity="0 0 0"', 'gravity="0 0 -9.81"').replace('damping="0.002"', 'damping="0.05"')
    text = text.replace('value="1e8"', 'value="2e9"').replace('size="0 0.01 0.001"', f'size="{size}"')
    path = tmp_path / "belt.xml"
    path.write_text(text)
    w = World(str(path), dt=1e-2, mass_damping=2.0)
    w.step(400)
    rod, = w.rods
    sag = 0.3 - w.positions(0)[-1, 2]
    assert abs(sag - plugin_sag) < 0.02 * rod.length
    if size == "0 0.001 0.01":
        q, lp = rod.material.line_density * 9.81, rod.length - 0.5 * rod.rest_len[0]
        assert sag == pytest.approx(q * lp ** 4 / (8 * 2e9 * 0.002 * 0.02 ** 3 / 12), rel=1e-2)


def test_each_model_declares_its_rods_held_as_written():
    got = {}
    for name in ALL:
        w = world(name)
        got[name] = [(e.name, e.start, e.start_body, e.end, e.end_body) for e in w._entries]
    assert got == {
        "ball_pinned": [("cable", "pin", None, "pin", "roller")],
        "belt_motor": [("beltcable", "clamp", "beltB_first", "clamp", "beltB_last")],
        "flexcomp_cable": [("rope", "clamp", None, "free", None)],
        "helix_free": [("hcable", "free", None, "free", None)],
        "s_curve_slider": [("cable", "clamp", "B_first", "pin", "slider")],
        "two_cables": [("acable", "clamp", "aB_first", "free", None), ("bcable", "clamp", "bB_first", "free", None)],
    }


@pytest.mark.parametrize("dt", [None, 1e-2])
@pytest.mark.parametrize("name", ALL)
def test_every_model_steps_stable_at_its_own_dt_and_at_1e_2(name, dt):
    """0.3 s of each model (a motor on the belt's S_last): no divergence (World raises one),
    no rod through the floor (its centreline less than a radius into it: the helix lands at
    2.4 m/s, 2.4 cm a step at dt 1e-2), and every rod's edges within 1 % of their rest lengths.
    The helix is looked at 0.4 s in, once its landing is over: it touches the floor at 0.24 s,
    its lowest vertex dips 6 mm (0.275 s), is back above -r by 0.325 s and at rest 2.5 mm up
    from 0.375 s (at 0.3 s: -0.4 mm before its turning edges were kept at their first-order
    lengths, -3.3 mm since, the landing less damped; 9.4 mm at worst, both)."""
    w = world(name, dt=dt)
    w.compile()
    if name == "belt_motor":
        w.data.ctrl[:] = 0.002
    w.step(int(round((0.4 if name == "helix_free" else 0.3) / w.model.opt.timestep)))
    for i, rod in enumerate(w.rods):
        x = w.positions(i)
        strain = np.linalg.norm(np.diff(x, axis=0), axis=1) / rod.rest_len - 1
        assert np.abs(strain).max() < 1e-2
        assert x[:, 2].min() > -rod.material.radius


@pytest.mark.parametrize("dt", [None, 1e-2])
def test_the_belt_whose_free_b_last_falls_under_gravity_lands_stable(tmp_path, dt):
    """The belt with gravity on and its motor twisting: B_last is a free body clamping the
    belt's end, so the belt hangs from its welded start and its end falls to the floor. 1 s:
    stable, edges within 1 % of their rest lengths, the end lying on the floor (its centre
    below 1 cm, above -r: the floor is at 0, the belt 1 mm thick). Before the rods'
    reaction on a holder used MuJoCo's current com positions (derods.sim.integrators.
    Step.elastic), this diverged at t = 0.07 s at every dt (edge strain 4-23)."""
    text = (MODELS / "belt_motor.xml").read_text().replace(' gravity="0 0 0"', "")
    path = tmp_path / "belt.xml"
    path.write_text(text)
    w = World(str(path), dt=dt) if dt else World(str(path))
    w.compile()
    w.data.ctrl[:] = 0.002
    w.step(int(round(1.0 / w.model.opt.timestep)))
    rod, = w.rods
    x = w.positions(0)
    strain = np.linalg.norm(np.diff(x, axis=0), axis=1) / rod.rest_len - 1
    assert np.abs(strain).max() < 1e-2
    assert -rod.material.radius < x[-1, 2] < 0.01


def test_the_twisted_belt_turns_by_t_l_over_g_j():
    """A torque T on S_last (a motor about the belt's tangent) turns B_last by T L' / (G J),
    L' the length between the middles of the held end edges, within 0.5 % (measured -0.00 %)."""
    w = world("belt_motor", dt=1e-2)
    w.compile()
    torque = 0.002
    w.data.ctrl[:] = torque
    b = w.model.body("beltB_last").id
    r0 = w.data.xmat[b].reshape(3, 3).copy()
    w.step(150)
    rel = r0.T @ w.data.xmat[b].reshape(3, 3)
    turn = math.atan2(rel[2, 1], rel[1, 1])
    rod, = w.rods
    expected = torque * (rod.length - rod.rest_len[-1]) / rod.material.beta
    assert turn == pytest.approx(expected, rel=5e-3)


@pytest.mark.parametrize("name, rods", [("two_cables", ["acable", "bcable"]), ("flexcomp_cable", ["rope"])])
def test_cantilevers_sag_as_the_closed_form(name, rods):
    """Welded at their start, sagging under their weight: tip sag q L'^4 / (8 E I) within 1 %
    (L' from the middle of the clamped edge; measured -0.21, -0.10, -0.27 %)."""
    w = world(name, dt=1e-2)
    w.step(300)
    for r in rods:
        rod = w.rods[w.rod_names.index(r)]
        x = w.positions(r)
        lp = rod.length - 0.5 * rod.rest_len[0]
        sag = rod.material.line_density * 9.81 * lp ** 4 / (8 * rod.material.alpha)
        assert x[0, 2] - x[-1, 2] == pytest.approx(sag, rel=1e-2)


def test_a_cables_written_contact_attributes_reach_its_flex():
    """The helix's geom writes friction, condim, solref, solimp: its collision flex has them;
    the S-curve's writes none: derods' ContactParams (friction 1, solref 0.005)."""
    w = world("helix_free")
    m = w.model
    f = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, "hcable")
    np.testing.assert_allclose(m.flex_friction[f], [0.8, 0.005, 0.0001])
    np.testing.assert_allclose(m.flex_solref[f], [0.01, 1.0])
    np.testing.assert_allclose(m.flex_solimp[f], [0.9, 0.95, 0.001, 0.5, 2.0])
    assert m.flex_condim[f] == 3
    m = world("s_curve_slider").model
    np.testing.assert_allclose(m.flex_friction[0], [1.0, 0.005, 0.0001])
    np.testing.assert_allclose(m.flex_solref[0], [0.005, 1.0])


def test_a_flat_cable_is_naturally_straight():
    """flat="true": the S-curve starts bent with a straight rest shape (a bending energy)."""
    rod = world("s_curve_slider").rods[0]
    assert rod.rest_curvature is None and "bend_isotropic" in rod.active_terms
    helix = world("helix_free").rods[0]
    assert helix.rest_curvature is not None


def test_a_sensor_on_s_last_reads_the_cables_end():
    """two_cables' framepos sensors name aS_last and bS_last: they read the end vertices."""
    w = world("two_cables", dt=1e-2)
    w.step(20)
    mujoco.mj_forward(w.model, w.data)
    a = w.data.sensor("a_tip").data
    np.testing.assert_allclose(a, w.positions("acable")[-1], atol=1e-9)


def test_the_flexcomps_points_are_mujocos():
    """rods_from="flexcomp": the rod's vertices are where MuJoCo 4 compiles the flexcomp's."""
    import xml.etree.ElementTree as ET

    path = MODELS / "flexcomp_cable.xml"
    root = ET.parse(path).getroot()
    root.find("option").set("integrator", "Euler")
    m = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    w = world("flexcomp_cable")
    np.testing.assert_allclose(w._entries[0].x0, d.flexvert_xpos[:m.flex_vertnum[0]], atol=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec, decls = mjcf_load.load(str(path))  # by default the flexcomp stays MuJoCo's
    assert decls == [] and spec.flex("rope") is not None


def test_a_composite_inside_a_moved_body_is_placed_in_its_frame(tmp_path):
    """A composite under a body at (1, 2, 3) turned 90 degrees about z: the rod starts at the
    body's pose applied to the offset, and B_last (referenced by a motor) sits on its last edge."""
    xml = """<mujoco><extension><plugin plugin="mujoco.elasticity.cable"/></extension><worldbody>
      <body pos="1 2 3" euler="0 0 90"><geom size=".01" contype="0" conaffinity="0"/>
        <composite type="cable" prefix="c" curve="s" count="11 1 1" size="0.5" offset="0.1 0 0" initial="none">
          <plugin plugin="mujoco.elasticity.cable"><config key="bend" value="1e7"/><config key="twist" value="4e6"/>
          </plugin><geom type="capsule" size="0.004"/></composite></body></worldbody>
      <actuator><motor site="cS_last" gear="0 0 0 1 0 0"/></actuator></mujoco>"""
    path = tmp_path / "moved.xml"
    path.write_text(xml)
    w = World(str(path), gravity=(0, 0, 0))
    w.compile()
    x = w.positions("ccable")
    np.testing.assert_allclose(x[0], [1, 2.1, 3], atol=1e-12)
    np.testing.assert_allclose(x[-1], [1, 2.6, 3], atol=1e-12)
    np.testing.assert_allclose(w.data.xpos[w.model.body("cB_last").id], x[-2], atol=1e-12)
    w.step(5)
    np.testing.assert_allclose(w.positions("ccable"), x, atol=1e-9)  # nothing acts on it


@pytest.mark.filterwarnings("ignore:.*instead of this equality")
def test_keyframes_keep_the_scenes_joints_and_drop_the_cables(tmp_path):
    """A 3.x keyframe's qpos is laid out for the jointed cable (39 ball joints, then the rail):
    the rail's value reaches derods' model, the cable's identity quaternions are the rod at
    rest; a key that bends the cable says its cable part is dropped; ctrl is kept."""
    rest = " ".join(["1 0 0 0"] * 39)
    bent = " ".join(["0.9998 0.02 0 0"] * 39)
    text = (MODELS / "s_curve_slider.xml").read_text().replace("</mujoco>", f"""  <keyframe>
    <key name="pushed" qpos="{rest} -0.05" ctrl="-0.05"/>
    <key name="bent" qpos="{bent} 0.02"/>
  </keyframe>
</mujoco>""")
    path = tmp_path / "keys.xml"
    path.write_text(text)
    with pytest.warns(UserWarning, match=r"keyframes \['bent'\]: their cables' joint values"):
        w = World(str(path))
    m, d = w.model, w.data
    rail = m.jnt_qposadr[m.joint("rail").id]
    assert m.key("pushed").qpos[rail] == -0.05 and m.key("bent").qpos[rail] == 0.02
    assert m.key("pushed").ctrl.tolist() == [-0.05]
    mujoco.mj_resetDataKeyframe(m, d, m.key("pushed").id)
    assert d.qpos[rail] == -0.05
    free = np.ones(m.nq, dtype=bool)
    free[rail] = False
    np.testing.assert_array_equal(m.key("pushed").qpos[free], m.qpos0[free])


_PAD = """<mujoco>
  <option timestep="2e-3"/>
  <extension><plugin plugin="mujoco.elasticity.cable"/></extension>
  <worldbody>
    <body name="pad" pos="0.49 0 0.235"><geom name="padgeom" type="box" size="0.03 0.05 0.005"/></body>
    <composite type="cable" curve="s" count="11 1 1" size="0.5" offset="0 0 0.25" initial="none">
      <plugin plugin="mujoco.elasticity.cable"><config key="bend" value="1e7"/><config key="twist" value="4e6"/></plugin>
      <geom type="capsule" size="0.004" density="1000"/>
    </composite>
  </worldbody>
  {contact}
</mujoco>"""


@pytest.mark.parametrize("mode", ["implicit", "alpha"])
@pytest.mark.parametrize("excluded", [False, True])
def test_a_contact_exclude_naming_b_last_keeps_the_last_edge_off_that_body(tmp_path, excluded, mode):
    """A 0.5 m cable clamped at its start, 1 cm above a small pad under its last segment:
    without an exclude it sags onto the pad (implicit: at rest, its tip 7.7 mm above the pad's
    top), the last edge touching it; with
    ``<exclude body1="B_last" body2="pad"/>``, as in MuJoCo 3.x the last segment goes through
    the pad (MuJoCo's body exclusion does not reach a flex's elements: derods marks those
    contacts, derods.sim.exclusion) and the tip hangs at the free cantilever's sag, 0.138 m."""
    w = world_of(tmp_path, _PAD.format(contact='<contact><exclude body1="B_last" body2="pad"/></contact>'
                                       if excluded else ""), mode=mode)
    m, d = w.model, w.data
    pad, last = m.geom("padgeom").id, len(w.rods[0].rest_len) - 1
    touches = 0
    for _ in range(500):
        w.step()
        con = d.contact
        on_pad = (con.geom == pad).any(axis=1) & (con.elem == last).any(axis=1) & (con.exclude == 0)
        touches += int(on_pad.sum())
    tip = w.positions(0)[-1, 2]
    if excluded:
        assert touches == 0
        assert tip < 0.2
    else:
        assert touches > 0
        assert tip > 0.24  # on the pad (the alpha mode's still bounces there at 1 s)


def test_the_stress_colours_read_the_moment_as_the_cable_plugin_does():
    """``vmax`` colours a rod by its elastic moment [N m] (MuJoCo's cable plugin: the joints'
    moment on a jet scale up to vmax). A straight rod bent into an arc of radius R carries
    E I / R at its inner edges (DER's 2 tan(phi/2) per joint: within (phi/2)^2 / 3, phi the
    turn per joint, here 1e-3 relative; bending="angle": exactly); twisted by Theta over L it
    carries G J Theta / L; at rest it carries none; the scale runs blue (0) to red (vmax)."""
    import dataclasses

    import derods
    from derods import shapes
    from derods.apps.mjcf_run import stress_painter
    from derods.viz import overlay

    mat = derods.Material(young=1e7, radius=0.005)
    rod = derods.Rod(shapes.straight(0.5, 50), mat)
    w = World(gravity=(0.0, 0.0, 0.0))
    w.add_rod(rod, start="clamp", end="clamp")
    w.compile()
    state = w.rod_state(0)
    assert np.allclose(overlay.internal_moment(rod, w.positions(0), state), 0.0, atol=1e-12)
    radius = 0.4
    s = np.linspace(0.0, 0.5, 51)
    arc = np.stack([radius * np.sin(s / radius), 0 * s, radius * (1 - np.cos(s / radius))], axis=1)
    w.set_positions(0, arc)
    moment = overlay.internal_moment(rod, arc, w.rod_state(0))
    np.testing.assert_allclose(moment[1:-1], mat.alpha / radius, rtol=1e-3)
    # Bending by the turning angle, the arc's turn per joint is h / R: alpha / R to round-off.
    by_angle = overlay.internal_moment(dataclasses.replace(rod, bending="angle"), arc, w.rod_state(0))
    np.testing.assert_allclose(by_angle[1:-1], mat.alpha / radius, rtol=1e-12)
    flat = derods.Material(young=1e7, radius=0.005, radius2=0.004)  # anisotropic: it carries the twist term
    band = derods.Rod(shapes.straight(0.5, 50), flat)
    assert "twist" in band.active_terms
    turned = dataclasses.replace(state, theta=np.linspace(0.0, 1.0, 50))  # 1 rad over the 49 joints' 0.49 m
    twisted = overlay.internal_moment(band, band.rest_x, turned)
    np.testing.assert_allclose(twisted[1:-1], flat.beta / 0.49, rtol=1e-9)
    np.testing.assert_allclose(overlay.jet_colours(np.array([0.0, 2.0]), 1.0)[:, :3], [[0, 0, 1], [1, 0, 0]])
    assert stress_painter(world("helix_free")) is not None  # its plugin sets vmax
    assert stress_painter(world("s_curve_slider")) is None


_SAGGING = """<mujoco>
  <option timestep="2e-3"/>
  <extension><plugin plugin="mujoco.elasticity.cable"/></extension>
  <worldbody>
    <composite type="cable" curve="s" count="21 1 1" size="0.5" offset="0 0 0.5" initial="none">
      <plugin plugin="mujoco.elasticity.cable"><config key="bend" value="1e6"/><config key="twist" value="4e5"/></plugin>
      <geom type="capsule" size="0.004" density="1000"/>
    </composite>
  </worldbody>
  <sensor><framequat name="end_turn" objtype="site" objname="S_last"/>
          <framepos name="end_at" objtype="site" objname="S_last"/></sensor>
</mujoco>"""


def test_a_read_only_s_last_turns_with_the_cables_end(tmp_path):
    """A cantilever cable sagging under gravity; a framequat sensor on S_last (only read, so
    derods makes it a mocap body it poses every step, derods.sim.riders): its x axis stays
    along the end edge as the end turns down (MuJoCo 3.x's end body has its x axis along
    its segment), to round-off, and its position on the end vertex; until then it kept its
    starting orientation (the end turned 1.5 rad here)."""
    w = world_of(tmp_path, _SAGGING)
    w.step(150)
    mujoco.mj_forward(w.model, w.data)
    x = w.positions(0)
    tangent = (x[-1] - x[-2]) / np.linalg.norm(x[-1] - x[-2])
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, w.data.sensor("end_turn").data)
    axis = mat.reshape(3, 3)[:, 0]
    np.testing.assert_allclose(axis, tangent, atol=1e-12)
    np.testing.assert_allclose(w.data.sensor("end_at").data, x[-1], atol=1e-12)
    assert math.acos(np.clip(tangent[0], -1, 1)) > 0.2  # the end did turn


def test_a_keyframes_mocap_poses_cover_the_riding_bodies(tmp_path):
    """A file with a mocap body and a keyframe setting its pose, and a read-only S_last (a
    mocap body derods adds): the keyframe's poses are extended by the rider's starting pose
    (MuJoCo refuses a keyframe whose mocap poses do not match the mocap bodies)."""
    xml = _SAGGING.replace("<worldbody>", '<worldbody><body name="hand" mocap="true" pos="1 0 1"/>')
    xml = xml.replace("</sensor>", '</sensor><keyframe><key name="k" mpos="1 0 2" mquat="1 0 0 0"/></keyframe>')
    w = world_of(tmp_path, xml)
    np.testing.assert_allclose(w.model.key_mpos.reshape(-1, 3), [[1.0, 0.0, 2.0], [0.5, 0.0, 0.5]])
