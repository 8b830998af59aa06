"""derods/validation.py and the World's guard: what the public API refuses, and how.

Each row of BAD is a mistake a new user makes, the exception it must raise and the
parameter its message must name. Every row runs beside a twin world that never sees
the mistake: the world that refused it must be bit for bit where its twin is, and
step as its twin does afterwards.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from derods import (ContactParams, DivergenceError, InvalidIndexError, InvalidInputError, InvalidTypeError,
                    Material, Rod, SceneWarning, TwistBoundary, World, shapes)

#: A floor, a slider driven by a motor (a control), a mocap body and a box a rod can be
#: held by: every array a user may write between steps exists in this scene.
SCENE = """
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="slider" pos="0 1 0.3">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <geom type="box" size="0.05 0.05 0.05" mass="1"/>
    </body>
    <body name="target" mocap="true" pos="0 -1 0.5"><geom type="sphere" size="0.02" contype="0"
      conaffinity="0"/></body>
  </worldbody>
  <actuator><motor name="push" joint="slide"/></actuator>
</mujoco>
"""
MAT = Material(young=1e6, radius=0.01)
X = shapes.straight(0.5, 8, start=(0.0, 0.0, 0.2))
ROD = Rod(X, MAT)


def build(compile_it: bool = True) -> World:
    w = World(mujoco.MjSpec.from_string(SCENE), dt=1e-2)
    w.add_rod(Rod(X, MAT), "rope", start="clamp")
    if compile_it:
        w.step(3)
        w.data.ctrl[0] = 0.5
    return w


@pytest.fixture(scope="module")
def pair():
    """A compiled world and its twin, stepped alike."""
    return build(), build()


@pytest.fixture(scope="module")
def building():
    """A world not compiled yet, with one rod 'rope', for add_rod's refusals."""
    return build(compile_it=False)


def _state(w: World) -> bytes:
    d = w.data
    fr = w._step.frames
    return b"".join(a.tobytes() for a in (d.qpos, d.qvel, d.act, d.ctrl, d.xfrc_applied, d.mocap_pos,
                                          np.array([d.time]), fr.u, fr.t, fr.theta))


def _written(array: str, index, value):
    """Write ``value`` into data.<array>[index], step, and put the entry back."""
    def case(w):
        a = getattr(w.data, array)
        old = np.array(a[index])
        a[index] = value
        try:
            w.step()
        finally:
            a[index] = old
    return case


def _folded():
    x = shapes.straight(1.0, 5)
    x[3:] = x[2] - (x[3:] - x[2])
    return x


NAN, INF = math.nan, math.inf
CTRL = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [4, 0, 0]], dtype=float)

# (id, call, exception, parameter named in the message). "w": the compiled world of a
# pair; "b": a world still being built; calls without a world take it and ignore it.
BAD = [
    # Material
    ("young str", lambda w: Material(young="1e7"), InvalidTypeError, "young"),
    ("young negative", lambda w: Material(young=-1.0), InvalidInputError, "young"),
    ("young nan", lambda w: Material(young=NAN), InvalidInputError, "young"),
    ("young inf", lambda w: Material(young=INF), InvalidInputError, "young"),
    ("young None", lambda w: Material(young=None), InvalidTypeError, "young"),
    ("young beyond diamond", lambda w: Material(young=1e14), InvalidInputError, "young"),
    ("density zero", lambda w: Material(young=1e6, density=0.0), InvalidInputError, "density"),
    ("density str", lambda w: Material(young=1e6, density="1000"), InvalidTypeError, "density"),
    ("radius negative", lambda w: Material(young=1e6, radius=-0.01), InvalidInputError, "radius"),
    ("radius list", lambda w: Material(young=1e6, radius=[0.01]), InvalidTypeError, "radius"),
    ("radius2 zero", lambda w: Material(young=1e6, radius2=0.0), InvalidInputError, "radius2"),
    ("shear negative", lambda w: Material(young=1e6, shear=-1.0), InvalidInputError, "shear"),
    ("poisson above 0.5", lambda w: Material(young=1e6, poisson=0.7), InvalidInputError, "poisson"),
    ("poisson bool", lambda w: Material(young=1e6, poisson=True), InvalidTypeError, "poisson"),
    # Rod
    ("material a number", lambda w: Rod(X, 5.0), InvalidTypeError, "material"),
    ("rest_x str", lambda w: Rod("abc", MAT), InvalidTypeError, "rest_x"),
    ("rest_x one edge", lambda w: Rod(X[:2], MAT), InvalidInputError, "rest_x"),
    ("rest_x nan", lambda w: Rod(np.where(np.arange(27).reshape(9, 3) == 4, NAN, X), MAT), InvalidInputError,
     "rest_x"),
    ("rest_x repeated vertex", lambda w: Rod(np.vstack([X[:3], X[2:]]), MAT), InvalidInputError, "rest_x"),
    ("rest_x 2-D points", lambda w: Rod(X[:, :2], MAT), InvalidInputError, "rest_x"),
    ("rest_x folded", lambda w: Rod(_folded(), MAT), InvalidInputError, "rest_x"),
    ("closed str", lambda w: Rod(X, MAT, closed="yes"), InvalidTypeError, "closed"),
    ("natural_curvature 'False'", lambda w: Rod(X, MAT, natural_curvature="False"), InvalidTypeError,
     "natural_curvature"),
    ("rest_twist nan", lambda w: Rod(X, MAT, rest_twist=NAN), InvalidInputError, "rest_twist"),
    ("rest_twist str", lambda w: Rod(X, MAT, rest_twist="0"), InvalidTypeError, "rest_twist"),
    ("rest_twist wrong length", lambda w: Rod(X, MAT, rest_twist=np.zeros(3)), InvalidInputError, "rest_twist"),
    ("rest_twist nan entry", lambda w: Rod(X, MAT, rest_twist=np.r_[0.0, NAN, np.zeros(5)]), InvalidInputError,
     "rest_twist"),
    ("stretch_stiffness negative", lambda w: Rod(X, MAT, stretch_stiffness=-1.0), InvalidInputError,
     "stretch_stiffness"),
    ("u0 zero", lambda w: Rod(X, MAT, u0=(0.0, 0.0, 0.0)), InvalidInputError, "u0"),
    ("u0 two numbers", lambda w: Rod(X, MAT, u0=(1.0, 0.0)), InvalidInputError, "u0"),
    ("boundary str", lambda w: Rod(X, MAT, boundary="clamped"), InvalidTypeError, "boundary"),
    ("bending unknown", lambda w: Rod(X, MAT, bending="curvature"), InvalidInputError, "bending"),
    ("bending not a str", lambda w: Rod(X, MAT, bending=True), InvalidTypeError, "bending"),
    ("closed rod, free boundary", lambda w: Rod(shapes.circle(0.1, 8), MAT, closed=True), InvalidInputError,
     "boundary"),
    # Rod's methods
    ("advance state None", lambda w: ROD.advance(None, X), InvalidTypeError, "state"),
    ("advance x wrong shape", lambda w: ROD.advance(ROD.rest_state(), X[:4]), InvalidInputError, "x"),
    ("advance x nan", lambda w: ROD.advance(ROD.rest_state(), X * NAN), InvalidInputError, "x"),
    ("derivatives order 3", lambda w: ROD.derivatives(ROD.rest_state(), order=3), InvalidInputError, "order"),
    ("derivatives terms str", lambda w: ROD.derivatives(ROD.rest_state(), terms="stretch"), InvalidTypeError,
     "terms"),
    ("energy of another rod's state", lambda w: ROD.energy(Rod(shapes.straight(1.0, 4), MAT).rest_state()),
     InvalidInputError, "state"),
    ("with_boundary str", lambda w: ROD.with_boundary("free"), InvalidTypeError, "boundary"),
    ("step_terms boundary str", lambda w: ROD.step_terms(ROD.rest_state(), X, boundary="free"), InvalidTypeError,
     "boundary"),
    # TwistBoundary
    ("boundary kind", lambda w: TwistBoundary("glued"), InvalidInputError, "kind"),
    ("clamped without angles", lambda w: TwistBoundary("clamped"), InvalidInputError, "theta_first"),
    ("theta_first nan", lambda w: TwistBoundary("clamped", NAN, 0.0), InvalidInputError, "theta_first"),
    ("total_twist str", lambda w: TwistBoundary("ring", total_twist="1"), InvalidTypeError, "total_twist"),
    # ContactParams
    ("friction negative", lambda w: ContactParams(friction=-1.0), InvalidInputError, "friction"),
    ("friction str", lambda w: ContactParams(friction="1"), InvalidTypeError, "friction"),
    ("solimp out of range", lambda w: ContactParams(solimp=(1.5, -1, 0, 0.5, 2)), InvalidInputError, "solimp"),
    ("solimp two values", lambda w: ContactParams(solimp=(0.9, 0.95)), InvalidInputError, "solimp"),
    ("priority not whole", lambda w: ContactParams(priority=1.5), InvalidInputError, "priority"),
    ("solimp power below 1", lambda w: ContactParams(solimp=(0.9, 0.95, 0.001, 0.5, 0.5)), InvalidInputError,
     "solimp"),
    ("solref one value", lambda w: ContactParams(solref=(0.005,)), InvalidInputError, "solref"),
    ("solref nan", lambda w: ContactParams(solref=(0.005, NAN)), InvalidInputError, "solref"),
    ("solref mixed signs", lambda w: ContactParams(solref=(-1.0, 1.0)), InvalidInputError, "solref"),
    ("condim 2", lambda w: ContactParams(condim=2), InvalidInputError, "condim"),
    ("condim 3.5", lambda w: ContactParams(condim=3.5), InvalidInputError, "condim"),
    ("margin negative", lambda w: ContactParams(margin=-0.01), InvalidInputError, "margin"),
    ("self_collision str", lambda w: ContactParams(self_collision="no"), InvalidTypeError, "self_collision"),
    ("rod_rod str", lambda w: ContactParams(rod_rod="yes"), InvalidTypeError, "rod_rod"),
    # World
    ("dt str", lambda w: World(dt="0.01"), InvalidTypeError, "dt"),
    ("dt zero", lambda w: World(dt=0.0), InvalidInputError, "dt"),
    ("dt nan", lambda w: World(dt=NAN), InvalidInputError, "dt"),
    ("dt negative", lambda w: World(dt=-1.0), InvalidInputError, "dt"),
    ("mode unknown", lambda w: World(mode="fast"), InvalidInputError, "mode"),
    ("mode None", lambda w: World(mode=None), InvalidTypeError, "mode"),
    ("integrator rk5", lambda w: World(integrator="rk5"), InvalidInputError, "integrator"),
    ("integrator number", lambda w: World(integrator=4), InvalidTypeError, "integrator"),
    ("gravity two numbers", lambda w: World(gravity=(0.0, -9.81)), InvalidInputError, "gravity"),
    ("gravity str", lambda w: World(gravity="down"), InvalidTypeError, "gravity"),
    ("mass_damping negative", lambda w: World(mass_damping=-1.0), InvalidInputError, "mass_damping"),
    ("stiffness_damping inf", lambda w: World(stiffness_damping=INF), InvalidInputError, "stiffness_damping"),
    ("contact a dict", lambda w: World(contact={"friction": 1.0}), InvalidTypeError, "contact"),
    ("strain_limit zero", lambda w: World(strain_limit=0.0), InvalidInputError, "strain_limit"),
    ("scene a number", lambda w: World(42), InvalidTypeError, "scene"),
    ("scene missing file", lambda w: World("/nonexistent/scene.xml"), InvalidInputError, "scene"),
    ("scene_checks str", lambda w: World(scene_checks="no"), InvalidTypeError, "scene_checks"),
    # add_rod, on a world being built
    ("b: rod a number", lambda b: b.add_rod(5.0), InvalidTypeError, "rod"),
    ("b: start unknown", lambda b: b.add_rod(Rod(X, MAT), "r2", start="glue"), InvalidInputError, "start"),
    ("b: end None", lambda b: b.add_rod(Rod(X, MAT), "r2", end=None), InvalidTypeError, "end"),
    ("b: name taken", lambda b: b.add_rod(Rod(X, MAT), "rope"), InvalidInputError, "name"),
    ("b: name of a vertex body", lambda b: b.add_rod(Rod(X, MAT), "rope_1"), InvalidInputError, "name"),
    ("b: name a number", lambda b: b.add_rod(Rod(X, MAT), 5), InvalidTypeError, "name"),
    ("b: name with a space", lambda b: b.add_rod(Rod(X, MAT), "my rope"), InvalidInputError, "name"),
    ("b: name of a scene body", lambda b: b.add_rod(Rod(X, MAT), "slider"), InvalidInputError, "name"),
    ("b: rgba three values", lambda b: b.add_rod(Rod(X, MAT), "r2", rgba=(1, 0, 0)), InvalidInputError, "rgba"),
    ("b: rgba above 1", lambda b: b.add_rod(Rod(X, MAT), "r2", rgba=(1, 0, 0, 2)), InvalidInputError, "rgba"),
    ("b: x wrong shape", lambda b: b.add_rod(Rod(X, MAT), "r2", x=X[:5]), InvalidInputError, "x"),
    ("b: x nan", lambda b: b.add_rod(Rod(X, MAT), "r2", x=X * NAN), InvalidInputError, "x"),
    ("b: x folded", lambda b: b.add_rod(Rod(shapes.straight(1.0, 5), MAT), "r2", x=_folded()), InvalidInputError,
     "x"),
    ("b: start_body unknown", lambda b: b.add_rod(Rod(X, MAT), "r2", start="pin", start_body="nobody"),
     InvalidInputError, "start_body"),
    ("b: start_body on a free end", lambda b: b.add_rod(Rod(X, MAT), "r2", start_body="slider"),
     InvalidInputError, "start_body"),
    ("b: start_body a number", lambda b: b.add_rod(Rod(X, MAT), "r2", start="pin", start_body=3),
     InvalidTypeError, "start_body"),
    ("b: a ring pinned", lambda b: b.add_rod(Rod(shapes.circle(0.1, 8), MAT, closed=True,
                                                 boundary=TwistBoundary("ring")), "r2", start="pin"),
     InvalidInputError, "start"),
    ("b: a batch of rods", lambda b: b.add_rod(Rod(np.stack([X, X + 1.0]), MAT), "r2"), InvalidInputError, "rod"),
    ("b: every vertex held", lambda b: b.add_rod(Rod(X[:3], MAT), "r2", start="clamp", end="pin"),
     InvalidInputError, "rod 'r2'"),
    # a compiled world's methods
    ("w: step negative", lambda w: w.step(-5), InvalidInputError, "n_steps"),
    ("w: step fractional", lambda w: w.step(2.5), InvalidInputError, "n_steps"),
    ("w: step str", lambda w: w.step("10"), InvalidTypeError, "n_steps"),
    ("w: rod name unknown", lambda w: w.positions("nope"), InvalidInputError, "rod"),
    ("w: rod index out of range", lambda w: w.positions(7), InvalidIndexError, "rod"),
    ("w: rod index fractional", lambda w: w.velocities(1.5), InvalidTypeError, "rod"),
    ("w: set_positions nan", lambda w: w.set_positions(0, X * NAN), InvalidInputError, "x"),
    ("w: set_positions wrong shape", lambda w: w.set_positions(0, X[:4]), InvalidInputError, "x"),
    ("w: set_velocities nan", lambda w: w.set_velocities(0, np.full_like(X, NAN)), InvalidInputError, "v"),
    ("w: set_velocities str", lambda w: w.set_velocities(0, "fast"), InvalidTypeError, "v"),
    ("w: vertex out of range", lambda w: w.vertex_body(0, 99), InvalidIndexError, "vertex"),
    ("w: vertex str", lambda w: w.vertex_body(0, "tip"), InvalidTypeError, "vertex"),
    ("w: reaction end unknown", lambda w: w.reaction(0, end="middle"), InvalidInputError, "end"),
    ("w: add_rod after compile", lambda w: w.add_rod(Rod(X, MAT), "late"), InvalidInputError, "add_rod"),
    ("w: rod_state of no rod", lambda w: w.rod_state("ghost"), InvalidInputError, "rod"),
    # written into MuJoCo's data between steps
    ("w: qvel nan", _written("qvel", 4, NAN), DivergenceError, "qvel"),
    ("w: qpos inf", _written("qpos", 5, INF), DivergenceError, "qpos"),
    ("w: qpos huge", _written("qpos", 0, 1e11), DivergenceError, "qpos"),
    ("w: ctrl nan", _written("ctrl", 0, NAN), DivergenceError, "ctrl"),
    ("w: xfrc_applied nan", _written("xfrc_applied", (5, 2), NAN), DivergenceError, "xfrc_applied"),
    ("w: qfrc_applied nan", _written("qfrc_applied", 0, NAN), DivergenceError, "qfrc_applied"),
    ("w: mocap_pos nan", _written("mocap_pos", (0, 0), NAN), DivergenceError, "mocap_pos"),
    ("w: mocap_quat inf", _written("mocap_quat", (0, 1), INF), DivergenceError, "mocap_quat"),
    # shapes
    ("straight length str", lambda w: shapes.straight("1", 10), InvalidTypeError, "length"),
    ("straight one edge", lambda w: shapes.straight(1.0, 1), InvalidInputError, "n_edges"),
    ("straight n_edges str", lambda w: shapes.straight(1.0, "10"), InvalidTypeError, "n_edges"),
    ("straight direction zero", lambda w: shapes.straight(1.0, 10, direction=(0, 0, 0)), InvalidInputError,
     "direction"),
    ("straight start nan", lambda w: shapes.straight(1.0, 10, start=(0, NAN, 0)), InvalidInputError, "start"),
    ("circle radius negative", lambda w: shapes.circle(-1.0, 10), InvalidInputError, "radius"),
    ("circle normal str", lambda w: shapes.circle(1.0, 10, normal="z"), InvalidTypeError, "normal"),
    ("helix pitch nan", lambda w: shapes.helix(0.1, NAN, 2.0, 10), InvalidInputError, "pitch"),
    ("bezier control points shape", lambda w: shapes.bezier(CTRL[:3], 10), InvalidInputError, "control_points"),
    ("bezier continuity", lambda w: shapes.bezier(CTRL, 10, continuity="C2"), InvalidInputError, "continuity"),
    ("resample closed str", lambda w: shapes.resample(X, 10, closed="no"), InvalidTypeError, "closed"),
    ("cantilever clamped_ends 3", lambda w: shapes.cantilever(1.0, 10, clamped_ends=3), InvalidInputError,
     "clamped_ends"),
    ("bezier_eval derivative 4", lambda w: shapes.bezier_eval(CTRL, [0.5], derivative=4), InvalidInputError,
     "derivative"),
]


def test_the_table_covers_at_least_80_inputs():
    assert len(BAD) >= 80


@pytest.mark.parametrize("call,error,param", [row[1:] for row in BAD], ids=[row[0] for row in BAD])
def test_bad_input_is_refused_naming_the_parameter(call, error, param, pair, building):
    """The refusal has derods' type, names the parameter and its value's fault, and leaves the
    world as its twin is: same state now, same state after one more step."""
    w, twin = pair
    target = building if call.__code__.co_varnames[:1] == ("b",) else w
    rods_before = list(building.rod_names)
    assert _state(w) == _state(twin)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        with pytest.raises(error) as info:
            call(target)
    assert type(info.value).__module__.startswith("derods")
    assert param in str(info.value), str(info.value)
    assert building.rod_names == rods_before
    assert _state(w) == _state(twin)
    w.step()
    twin.step()
    assert _state(w) == _state(twin)


def test_types_are_value_and_type_errors():
    """A refusal is a ValueError; a refusal of the wrong kind of value is also a TypeError
    (code catching either keeps working)."""
    assert issubclass(InvalidInputError, ValueError)
    assert issubclass(InvalidTypeError, TypeError) and issubclass(InvalidTypeError, InvalidInputError)
    assert issubclass(InvalidIndexError, IndexError)
    with pytest.raises(InvalidTypeError, match=r"young must be a finite number > 0 \[Pa\], got '1e7' \(str\): "
                                               r"pass a float such as 10000000.0"):
        Material(young="1e7")


def test_the_refusing_world_still_builds_as_its_twin(building):
    """After every refused add_rod, the world being built compiles and steps as a world that
    never saw them."""
    twin = build(compile_it=False)
    building.step(5)
    twin.step(5)
    assert _state(building) == _state(twin)


def test_nan_in_qvel_stops_before_mujoco_resets_and_keeps_the_state():
    """Without the guard, MuJoCo resets the world to its start (time back to 0) on the next
    step and carries on. Now the step is refused, nothing moves, and once the entry is made
    finite the world steps on as if it had never been written."""
    w, twin = build(), build()
    w.step(5)
    twin.step(5)
    before = _state(w)
    x = w.positions().copy()
    k = int(w.dofs("rope")[3])  # vertex 3 (the clamp holds 0 and 1), x
    w.data.qvel[k] = NAN
    with pytest.raises(DivergenceError, match=rf"data\.qvel\[{k}\] \(rod 'rope', vertex 3, x\) is nan before step 9"):
        w.step()
    assert w.time == pytest.approx(0.08) and w.n_steps == 8
    np.testing.assert_array_equal(w.positions(), x)
    w.data.qvel[k] = twin.data.qvel[k]
    assert _state(w) == before
    w.step(3)
    twin.step(3)
    assert _state(w) == _state(twin)


@pytest.mark.parametrize("mode", ["alpha", "projection", "explicit"])
def test_a_refused_write_leaves_every_mode_stepping_as_before(mode):
    """What the alpha mode carries between steps (its last acceleration, whether it starts
    afresh) is kept with the state: a world that refused a NaN steps on as its twin."""
    def world():
        w = World(mujoco.MjSpec.from_string(SCENE), dt=1e-2 if mode != "explicit" else 1e-5, mode=mode)
        w.add_rod(Rod(X, MAT), "rope", start="clamp")
        w.step(4)
        return w

    w, twin = world(), world()
    k = int(w.dofs("rope")[5])
    w.data.qvel[k] = INF
    with pytest.raises(DivergenceError, match=rf"data\.qvel\[{k}\] \(rod 'rope', vertex 3, z\) is inf"):
        w.step()
    w.data.qvel[k] = twin.data.qvel[k]
    w.step(5)
    twin.step(5)
    assert _state(w) == _state(twin)


def test_a_step_mujoco_warns_about_is_undone_and_named():
    """A force of 1e13 N on the 1 kg slider makes its acceleration huge (BADQACC): the step
    is undone (time, positions and the rod's frames as before it), and the error names the
    warning and the joint, and points at what was given to it rather than at the step."""
    w = build()
    before = _state(w)
    w.data.xfrc_applied[w.model.body("slider").id, 0] = 1e13
    with pytest.raises(DivergenceError, match=r"the world diverged at step 4 .*BADQACC\) at dof 0, joint 'slide'.*"
                                              r"back at its state before step 4") as info:
        w.step()
    assert "smaller dt" not in str(info.value) and "xfrc_applied" in str(info.value)
    w.data.xfrc_applied[:] = 0.0
    assert _state(w) == before


def test_a_diverging_rod_is_put_back_where_the_step_began():
    """Explicit stepping far beyond its limit diverges; the world is back at the step's start."""
    w = World(dt=1e-2, mode="explicit")
    w.add_rod(Rod(shapes.cantilever(1.0, 20), Material(young=1e8)), "wire", start="clamp")
    with pytest.raises(DivergenceError, match=r"rod 'wire' diverged at step (\d+).*smaller dt.*back at its state "
                                              r"before step \1") as info:
        w.step(200)
    step = int(re.search(r"diverged at step (\d+)", str(info.value)).group(1))
    assert w.n_steps == step - 1
    assert w.time == pytest.approx(1e-2 * w.n_steps)
    assert np.all(np.isfinite(w.positions())) and np.all(np.isfinite(w.rod_state().theta))


def test_a_rod_stretched_between_its_holds_is_warned_of_and_blamed():
    """A rod pinned at both ends, started 50 % longer than its rest length: compile warns,
    and the divergence that follows (its edges spring back) is blamed on that initial
    shape in every mode, not on the step."""
    for mode in ("implicit", "alpha", "projection"):
        w = World(dt=1e-2, mode=mode)
        w.add_rod(Rod(X, MAT), "taut", start="pin", end="pin", x=X * np.array([1.5, 1.0, 1.0]))
        with pytest.warns(SceneWarning, match=r"rod 'taut' is held at both ends and starts 50 % longer"):
            w.compile()
        with pytest.raises(DivergenceError, match="started 50 % longer than its rest length") as info:
            w.step(10)
        assert "smaller dt" not in str(info.value) and "out of proportion" not in str(info.value)
        np.testing.assert_array_equal(w.positions(), X * np.array([1.5, 1.0, 1.0]))


def test_scene_checks_warn_and_can_be_silenced():
    """dt = 1 s over a floor (the rod would fall through on its first step) and a rod laid
    through a box are warned of, as the command line does; scene_checks=False silences both."""
    scene = SCENE.replace('<geom type="box" size="0.05 0.05 0.05" mass="1"/>',
                          '<geom name="crate" type="box" size="0.05 0.05 0.05" mass="1"/>')

    def world(dt, checks=True):
        w = World(mujoco.MjSpec.from_string(scene), dt=dt, scene_checks=checks)
        w.add_rod(Rod(shapes.straight(0.5, 10, start=(-0.25, 1.0, 0.3)), MAT), "through")
        return w

    with pytest.warns(SceneWarning) as got:
        world(1.0).compile()
    texts = [str(r.message) for r in got]
    assert any("dt 1 s lets a rod falling" in t for t in texts)
    assert any("rod 'through' starts inside crate" in t for t in texts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        world(1.0, checks=False).compile()


def test_valid_rows_stay_accepted():
    """What the table refuses is refused for its fault alone: the same calls with good
    values pass (a check that refused everything would pass the table)."""
    Material(young=1e7, density=1000, radius=0.01, radius2=0.005, shear=3e6)
    Rod(X, MAT, closed=False, natural_curvature=False, rest_twist=np.zeros(7), u0=(0, 1, 0))
    ContactParams(friction=0.0, solref=(-1000.0, -10.0), solimp=(0.9, 0.95, 0.001), condim=6, margin=0.0)
    World(dt=1e-3, mode="alpha", integrator="implicit", gravity=(0, 0, -1.62), strain_limit=math.inf)
    w = World(mujoco.MjSpec.from_string(SCENE))
    w.add_rod(Rod(X, MAT), "ro", rgba=(0.1, 0.2, 0.3, 1.0), start="pin", start_body="slider")
    w.add_rod(Rod(X + (0, 0.1, 0), MAT), "ro-2")
    w.step(100.0)  # a whole number of steps, as a float
    assert w.n_steps == 100
    assert shapes.straight(1.0, 10.0).shape == (11, 3)
    assert replace(ContactParams(), friction=0.5).friction == 0.5


def test_a_thin_obstacle_is_warned_of():
    """A 2 mm plate under a rod falling 1 m at dt = 1e-2 s: 44 mm per step at impact, more
    than the plate and the rod's diameter together (22 mm): contact may never be found."""
    scene = '<mujoco><worldbody><geom name="plate" type="box" size="0.5 0.5 0.001"/></worldbody></mujoco>'
    w = World(mujoco.MjSpec.from_string(scene), dt=1e-2)
    w.add_rod(Rod(shapes.straight(0.5, 10, start=(-0.25, 0.0, 1.0)), MAT), "falling")
    with pytest.warns(SceneWarning, match=r"plate is 2 mm thick .* moves 44\.\d mm in one step"):
        w.compile()
    calm = World(mujoco.MjSpec.from_string(scene), dt=1e-3)
    calm.add_rod(Rod(shapes.straight(0.5, 10, start=(-0.25, 0.0, 1.0)), MAT), "falling")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        calm.compile()


def test_an_end_inside_its_holder_is_not_warned_of():
    """A rod pinned inside the box that holds it sits there by design (a held edge does not
    collide with its holder); the same rod laid through a box that does not hold it is
    warned of."""
    def world(held: bool):
        w = World(mujoco.MjSpec.from_string(SCENE), dt=1e-2)
        x = shapes.straight(0.5, 10, start=(0.0, 1.0, 0.3))  # starts at the slider's centre
        w.add_rod(Rod(x, MAT), "tail", start="pin" if held else "free", start_body="slider" if held else None)
        return w

    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneWarning)
        world(held=True).compile()
    with pytest.warns(SceneWarning, match=r"rod 'tail' starts inside"):
        world(held=False).compile()


def test_a_full_arena_says_how_much_memory_to_give_and_the_world_steps_on_with_it():
    """A step whose contacts do not fit MuJoCo's arena (CNSTRFULL) lost no solution: the
    message says so, names the arena and a size to give it (twice what it has), and with
    that size the same world steps. Measured: a 51-vertex cable lying on a floor makes 51
    contacts; at 60K bytes they do not fit, at 120K they do."""
    def world(memory):
        xml = (f'<mujoco><size memory="{memory}"/><option integrator="implicitfast"/><worldbody>'
               '<geom type="plane" size="2 2 0.1"/></worldbody></mujoco>')
        w = World(mujoco.MjSpec.from_string(xml), dt=1e-3)
        w.add_rod(Rod(shapes.straight(0.5, 50, start=(-0.25, 0.0, 0.0095)), Material(young=1e7, radius=0.01)), "cable")
        w.compile()
        return w

    small = world("60K")
    with warnings.catch_warnings(), pytest.raises(DivergenceError) as err:
        warnings.simplefilter("ignore")
        small.step()
    text = str(err.value)
    assert "CNSTRFULL" in text and "61440 bytes (model.narena) is full" in text and "diverged" not in text
    size = re.search(r'<size memory="(\w+)"/>', text).group(1)
    assert size == "120K" and small.n_steps == 0
    big = world(size)
    big.step(3)
    assert big.data.ncon == 51
