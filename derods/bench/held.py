"""Rods held by moving bodies under gravity and in contact (issue 27): scenes, criteria, runs.

A frozen :class:`Case` names a scenario, the holder's joint and mass, how the rod's start is
held and the rod; :func:`run` builds its scene (MJCF written here), steps it with
``World(spec, dt=dt)`` defaults (mode "auto", which picks "implicit"; default contacts,
friction 1, and strain limit; MuJoCo's Euler integrator and gravity (0, 0, -9.81) m/s^2)
and judges it. The rod: r = 3 mm, E = 1e7 Pa, rho = 1000 kg/m^3 (0.028 kg/m), LENGTH[scenario]
m, 32 edges; DURATION[scenario] s. Positions [m], SI throughout.

- "fall": a 4 cm box (holder "free": free joint; "slide": vertical slide) holding the rod's
  start at the middle of its +x face, the rod along +x, nothing to touch. ok: max over
  vertices i and steps of |(x_i(t) - x_i(0)) - (p(t) - p(0))| < FALL_TOL * L (p: the box's
  centre; in a uniform field the pair falls rigidly: exactly zero).
- "land": the free box, its bottom DROP above a floor (z = 0), the rod level at its height.
  ok: at the end the lowest vertex above r / 2, the box's lowest corner within REST_GAP of
  the floor, box corners and rod vertices slower than REST_SPEED.
- "drag": a 0.5 m cable on a floor along -x from a cart (slide along x) whose position
  servo's target moves TRAVEL along +x in RAMP s. ok: the tail moved more than TAIL_MOVE
  along x; the contact criterion.
- "edge": the cable from a cart on top of a ledge (a static box on the floor, top at
  LEDGE_TOP), over its edge and down its side, drawn back TRAVEL along -x. ok: the contact
  criterion against the box and the floor.
- "lift": the cable on a table (a static box, top at TABLE_TOP), its start on a cart on a
  vertical slide (gravity compensated) lifted LIFT in RAMP s. ok: the start lifted more
  than 3/4 of LIFT, the last LYING_SHARE of the vertices still lying (within r / 2 of
  resting height); the contact criterion against the table.
- The carts' contact criterion (:func:`_contact_failures`): no vertex centre ever more
  than r inside the surface (through it), and at the end every vertex centre more than
  r / 2 out of it (resting on it). While the cable hops along, MuJoCo's discrete
  detection finds a vertex moving at v only up to v h inside (at dt 1e-2 a cable on a
  mocap cart dips 2.4 mm below the floor): the holder "mocap" runs each cart scene with
  the cart a mocap body following the servo's target, the existing path, as the
  reference for what the contact model does without a holder's dofs.
- "swing": the rod hanging from a body ("hinge": on a hinge about y; "ball": a ball joint)
  ARM below the pivot, released from SWING_ANGLE. ok: no vertex ever HEIGHT_RISE above
  its start, the energy (kinetic + gravity + elastic) never above its start by more than
  ENERGY_RISE + h w (w = sqrt(g / ARM)) of the energy the swing releases: backward Euler
  dissipates, but MuJoCo's Euler integrator lets a pendulum's measured energy oscillate by
  ~h w / 2 (4.6 % at 1e4 kg, dt 1e-2).
- "span": the rod clamped to the world at its start, PIVOT high, level along +x, its end held
  (pin or clamp) by a free box (BOX) that nothing else holds: the box falls and swings below
  on the rod. ok: no vertex and not the box ever HEIGHT_RISE above its start (released at rest
  from its highest state, the pair cannot rise above it without gaining energy). A cable
  between a fixed point and a hanging weight; a 3.x cable model whose B_last is free.

The carts hold the cable's start CLEARANCE above its surface, the rest lying SINK into it
(contacts from the first step; at dist = 0 MuJoCo makes none and the cable falls h^2 g). A held
vertex touching the floor would make a contact row with no normal dof (the cart only
slides along the floor). Their servo is ``<position kp = 200 M kv = 20 M>``, the slide's
damping 1 M [N s/m], M the mass moved (cart + cable), so every cart mass tracks alike
(damping ratio 0.7); with the cart's mass alone a 1 g cart's servo (0.2 N/m) cannot pull
the cable's friction (0.14 N). A DivergenceError is recorded as unstable with its message.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import mujoco
import numpy as np

from .. import shapes
from ..sim.divergence import DivergenceError
from .held_scene import (ARM, BOX, CLEARANCE, DROP, DURATION, ENERGY_RISE, FALL_TOL, HEIGHT_RISE,  # noqa: F401
                         LEDGE_TOP, LENGTH, LIFT, LYING_SHARE, PIVOT, RAMP, REST_GAP, REST_SPEED, SCENARIOS, SINK,
                         SWING_ANGLE, TABLE_TOP, TAIL_MOVE, TRAVEL, Case, Scene, _box_body, _f, _world)


def _box_sdf(x: np.ndarray, center, half) -> np.ndarray:
    """Signed distance [m] of points x (k, 3) from an axis-aligned box (negative inside)."""
    q = np.abs(x - np.asarray(center)) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def _cart(case: Case, pos, axis: str, extra: str = "") -> tuple[str, str]:
    """A cart body "holder" at pos [m] on a slide "cart" along ``axis``, and its position
    servo's <actuator> block (gains and damping per kg of cart + cable, see the docstring);
    for the holder "mocap", a mocap body there (moved along the servo's target by the scene)."""
    if case.holder == "mocap":
        return (f'<body name="holder" mocap="true" pos="{_f(*pos)}"><geom type="box" size="0.01 0.01 0.01" '
                f'contype="0" conaffinity="0"/></body>'), ""
    m = case.mass + case.material.line_density * case.length
    return (f'<body name="holder" pos="{_f(*pos)}"{extra}><joint name="cart" type="slide" axis="{axis}" '
            f'damping="{_f(m)}"/><geom type="box" size="0.01 0.01 0.01" mass="{_f(case.mass)}" contype="0" '
            f'conaffinity="0"/></body>'), \
        f'<actuator><position joint="cart" kp="{_f(200 * m)}" kv="{_f(20 * m)}" ctrlrange="-1 1"/></actuator>'



def _fall(case: Case) -> Scene:
    joint = "<freejoint/>" if case.holder == "free" else '<joint type="slide" axis="0 0 1"/>'
    xml = _box_body(case, 1.0, joint, "" if case.collide else ' contype="0" conaffinity="0"')
    world, body = _world(case, xml, shapes.straight(case.length, case.n_edges, start=(BOX, 0.0, 1.0)))
    x0, p0 = world.positions("rod").copy(), world.data.xpos[body].copy()
    worst = [0.0]

    def after():
        rel = (world.positions("rod") - x0) - (world.data.xpos[body] - p0)  # positions() ran mj_kinematics
        worst[0] = max(worst[0], float(np.max(np.linalg.norm(rel, axis=1))))

    def judge():
        limit = FALL_TOL * case.length
        return {"relative_motion": worst[0], "limit": limit}, \
            [f"rod moved {worst[0]:.3g} m against the box (limit {limit:.3g} m)"] * (worst[0] >= limit)
    return Scene(world, body, None, after, judge, at_end=False)


def _land(case: Case) -> Scene:
    xml = '<geom name="floor" type="plane" size="2 2 0.1"/>' + _box_body(case, BOX + DROP, "<freejoint/>")
    world, body = _world(case, xml, shapes.straight(case.length, case.n_edges, start=(BOX, 0.0, BOX + DROP)))
    m, d = world.model, world.data
    corners = BOX * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
    dof = m.body_dofadr[body]

    def judge():
        low = float(world.positions("rod")[:, 2].min())
        bottom = float(np.min(d.xpos[body][2] + corners @ d.xmat[body].reshape(3, 3)[2]))
        box = float(np.linalg.norm(d.qvel[dof:dof + 3]) + np.linalg.norm(d.qvel[dof + 3:dof + 6]) * BOX * 3**0.5)
        rod = float(np.max(np.linalg.norm(world.velocities("rod"), axis=1)))
        bad = [f"lowest vertex at {low:.4g} m (below r/2)"] * (low <= case.radius / 2)
        bad += [f"box bottom at {bottom:.3g} m"] * (abs(bottom) > REST_GAP)
        bad += [f"not at rest: box {box:.3g} m/s, rod {rod:.3g} m/s"] * (max(box, rod) > REST_SPEED)
        return {"lowest_vertex": low, "box_bottom": bottom, "box_speed": box, "rod_speed": rod}, bad
    return Scene(world, body, None, None, judge)


def _cart_scene(world, body, travel, surface, axis) -> Scene:
    """Cart scenes' shared part: the servo's target (or the mocap cart) ramped ``travel`` [m]
    along ``axis`` (3,) over RAMP, and the least clearance over the run and at its end
    (``surface(x)``: each vertex centre's distance [m])."""
    d = world.data
    least = [np.inf]
    start = d.mocap_pos[0].copy() if len(d.mocap_pos) else None

    def before(t):
        if start is None:
            d.ctrl[0] = travel * min(t / RAMP, 1.0)
        else:
            d.mocap_pos[0] = start + np.asarray(axis) * travel * min(t / RAMP, 1.0)

    def after():
        least[0] = min(least[0], float(np.min(surface(world.positions("rod")))))
    return Scene(world, body, before, after, None,
                 extra={"x0": world.positions("rod").copy(), "least": least,
                        "at_end": lambda: float(np.min(surface(world.positions("rod"))))})


def _contact_failures(least: float, at_end: float, r: float, what: str) -> list[str]:
    """The cart scenes' contact criterion: the cable never through ``what`` during the motion
    (no vertex centre more than r inside: discrete detection finds a vertex moving at v
    only once it is up to v h in, as it does for a cable on a mocap cart), and resting on it
    at the end (every vertex centre more than r / 2 out, as the landing's)."""
    bad = [f"a vertex {-least:.3g} m inside the {what} during the run (through it: limit r)"] * (least <= -r)
    bad += [f"at the end a vertex {at_end:.4g} m from the {what} (limit r/2)"] * (at_end <= r / 2)
    return bad


def _drag(case: Case) -> Scene:
    r = case.radius
    cart, act = _cart(case, (0.0, 0.0, r + CLEARANCE), "1 0 0")
    x = shapes.straight(case.length, case.n_edges, start=(0.0, 0.0, r - SINK), direction=(-1.0, 0.0, 0.0))
    world, body = _world(case, ('<geom name="floor" type="plane" size="3 3 0.1"/>' + cart, act), x,
                         raised=CLEARANCE + SINK)
    sc = _cart_scene(world, body, TRAVEL, lambda x: x[:, 2], (1.0, 0.0, 0.0))

    def judge():
        tail, low, end = float(world.positions("rod")[-1, 0] - sc.extra["x0"][-1, 0]), sc.extra["least"][0], \
            sc.extra["at_end"]()
        bad = [f"tail moved {tail:.3g} m (need > {TAIL_MOVE:g})"] * (tail <= TAIL_MOVE)
        bad += _contact_failures(low, end, r, "floor")
        return {"tail_dx": tail, "lowest_vertex": low, "lowest_at_end": end}, bad
    sc.judge = judge
    return sc


def _edge(case: Case) -> Scene:
    r, top = case.radius, LEDGE_TOP
    rho = r + CLEARANCE  # the hanging part starts clear of the ledge's side
    center, half = (-0.3, 0.0, top / 2), (0.3, 0.15, top / 2)
    start = np.array([-0.1, 0.0, top + r - SINK])
    cart, act = _cart(case, start + [0.0, 0.0, CLEARANCE + SINK], "1 0 0")
    xml = (f'<geom name="floor" type="plane" size="3 3 0.1"/><geom name="ledge" type="box" pos="{_f(*center)}" '
           f'size="{_f(*half)}"/>' + cart, act)
    phi = np.linspace(0.0, np.pi / 2, 9)
    path = np.vstack([[start], np.stack([rho * np.sin(phi), 0 * phi, top + (r - SINK) * np.cos(phi)], axis=1)])
    hang = case.length - float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))  # the rest hangs
    path = np.vstack([path, [[rho, 0.0, top - hang]]])
    world, body = _world(case, xml, shapes.resample(path, case.n_edges), natural=False, raised=CLEARANCE + SINK)
    sc = _cart_scene(world, body, -TRAVEL, lambda x: np.minimum(_box_sdf(x, center, half), x[:, 2]),
                     (1.0, 0.0, 0.0))

    def judge():
        least, end = sc.extra["least"][0], sc.extra["at_end"]()
        rise = float(world.positions("rod")[-1, 2] - sc.extra["x0"][-1, 2])
        return {"least_clearance": least, "clearance_at_end": end, "tail_rise": rise}, \
            _contact_failures(least, end, r, "ledge")
    sc.judge = judge
    return sc


def _lift(case: Case) -> Scene:
    r, top = case.radius, TABLE_TOP
    center, half = (0.2, 0.0, top / 2), (0.4, 0.15, top / 2)
    cart, act = _cart(case, (0.0, 0.0, top + r + CLEARANCE), "0 0 1", ' gravcomp="1"')
    xml = (f'<geom name="table" type="box" pos="{_f(*center)}" size="{_f(*half)}"/>' + cart, act)
    x = shapes.straight(case.length, case.n_edges, start=(0.0, 0.0, top + r - SINK))
    world, body = _world(case, xml, x, raised=CLEARANCE + SINK)
    sc = _cart_scene(world, body, LIFT, lambda x: _box_sdf(x, center, half), (0.0, 0.0, 1.0))

    def judge():
        x = world.positions("rod")
        rise, least, end = float(x[0, 2] - sc.extra["x0"][0, 2]), sc.extra["least"][0], sc.extra["at_end"]()
        k = max(1, int(round(LYING_SHARE * len(x))))
        lying = float(np.max(np.abs(x[-k:, 2] - (top + r))))
        bad = [f"start lifted {rise:.3g} m (need > {0.75 * LIFT:g})"] * (rise <= 0.75 * LIFT)
        bad += [f"tail {lying:.3g} m off its resting height"] * (lying >= r / 2)
        bad += _contact_failures(least, end, r, "table")
        return {"start_rise": rise, "tail_off_table": lying, "least_clearance": least, "clearance_at_end": end}, bad
    sc.judge = judge
    return sc


def _swing(case: Case) -> Scene:
    a = SWING_ANGLE
    down = np.array([-math.sin(a), 0.0, -math.cos(a)])  # the arm's direction, turned a about y
    pos = np.array([0.0, 0.0, PIVOT]) + ARM * down
    joint = "hinge" if case.holder == "hinge" else "ball"
    xml = (f'<body name="holder" pos="{_f(*pos)}" quat="{_f(math.cos(a / 2), 0, math.sin(a / 2), 0)}">'
           f'<joint type="{joint}" axis="0 1 0" pos="0 0 {ARM}"/>'
           f'<geom type="sphere" size="0.01" mass="{_f(case.mass)}" contype="0" conaffinity="0"/></body>')
    world, body = _world(case, xml, pos + shapes.straight(case.length, case.n_edges, direction=down))
    m, d = world.model, world.data
    g, mv = np.array(m.opt.gravity), np.zeros(m.nv)
    state = {"e": [], "top0": float(world.positions("rod")[:, 2].max()), "rise": -np.inf, "pending": 0.0}
    # the energy [J] the swing releases: the holder and the rod's centre from SWING_ANGLE to hanging
    rod_mass = case.material.line_density * case.length
    released = 9.81 * (1 - math.cos(a)) * (case.mass * ARM + rod_mass * (ARM + case.length / 2))

    def before(t):
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)  # qM of the state now (the step's mj_forward recomputes all of it)
        mujoco.mj_mulM(m, d, mv, d.qvel)
        state["pending"] = 0.5 * float(d.qvel @ mv) - float(m.body_mass @ (d.xipos @ g))

    def after():
        # the step's rod terms hold the elastic energy of the state before it, the one `before` saw
        state["e"].append(state["pending"] + float(np.sum(world._step.terms.energy)))
        state["rise"] = max(state["rise"], float(world.positions("rod")[:, 2].max()) - state["top0"])

    def judge():
        e = state["e"]
        rise = (max(e) - e[0]) / released if e else float("nan")
        limit = ENERGY_RISE + case.dt * math.sqrt(9.81 / ARM)
        bad = [f"energy rose {rise:.3g} of the released {released:.3g} J (limit {limit:.3g})"] * (rise > limit)
        bad += [f"a vertex rose {state['rise']:.3g} m above its start"] * (state["rise"] > HEIGHT_RISE)
        return {"energy_rise": rise, "limit": limit, "height_rise": state["rise"]}, bad
    return Scene(world, body, before, after, judge, at_end=False, extra=state)


def _span(case: Case) -> Scene:
    r = case.length
    x = shapes.straight(r, case.n_edges, start=(0.0, 0.0, PIVOT))
    origin = x[-1] if case.end == "pin" else x[-2]  # the box's centre on the held vertex next to the rod
    world, body = _world(case, f'<body name="holder" pos="{_f(*origin)}"><freejoint/><geom type="box" '
                         f'size="{_f(BOX, BOX, BOX)}" mass="{_f(case.mass)}" contype="0" conaffinity="0"/></body>',
                         x, held_end=True)
    d = world.data
    state = {"top": max(float(x[:, 2].max()), PIVOT), "rise": -np.inf}

    def after():
        state["rise"] = max(state["rise"], float(world.positions("rod")[:, 2].max()) - state["top"],
                            float(d.xpos[body][2]) - PIVOT)

    def judge():
        bad = [f"a vertex or the box rose {state['rise']:.3g} m above its start"] * (state["rise"] > HEIGHT_RISE)
        return {"height_rise": state["rise"]}, bad
    return Scene(world, body, None, after, judge, at_end=False, extra=state)


BUILDERS = {"fall": _fall, "land": _land, "drag": _drag, "edge": _edge, "lift": _lift, "swing": _swing,
            "span": _span}


def build(case: Case) -> Scene:
    """The compiled scene of ``case`` (see the module docstring)."""
    return BUILDERS[case.scenario](case)


def run(case: Case) -> dict:
    """Build, step and judge one case. Returns a JSON-able record: the case's scenario,
    holder, mass [kg], end, dt [s], young [Pa], n_edges; ``ok`` (stable and the criterion
    met), ``stable`` (no DivergenceError, positions finite), ``values`` (the criterion's
    numbers, SI; up to the divergence for fall and swing, none for the others), ``note``
    (the divergence's message, or what failed), ``steps`` taken, ``wall_s`` [s] (build and run)."""
    t0 = time.perf_counter()
    sc = build(case)
    world, note, steps = sc.world, "", 0
    try:
        for k in range(case.steps):
            if sc.before is not None:
                sc.before(k * case.dt)
            world.step()
            steps += 1
            if sc.after is not None:
                sc.after()
            if k % 50 == 0 and not np.all(np.isfinite(world.data.qpos)):
                raise DivergenceError(f"positions not finite at step {k}")
    except DivergenceError as err:
        note = str(err)
    values, bad = sc.judge() if not note or not sc.at_end else ({}, [])
    rec = {k: getattr(case, k) for k in ("scenario", "holder", "mass", "end", "dt", "young", "n_edges")}
    values = {k: float(v) if math.isfinite(v) else None for k, v in values.items()}  # strict JSON
    rec.update(ok=not note and not bad, stable=not note, values=values,
               note=note or "; ".join(bad), steps=steps, wall_s=time.perf_counter() - t0)
    return rec


MASSES = (1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e4)   #: holder masses of the grid [kg]
#: span's, without 10 t: hanging from the 3 mm rod it would stretch it 35 % at rest (m g over
#: the inextensible stretch stiffness A 1e10 Pa), beyond what a rod model is for.
SPAN_MASSES = MASSES[:-1]
DTS = (1e-3, 5e-3, 1e-2)                             #: steps of the grid [s]
#: Scenarios whose criterion holds for any stiffness (the corners E x n cross these).
CORNER_SCENARIOS = ("fall", "land", "drag", "swing", "span")


def _masses(scenario: str, holder: str) -> tuple[float, ...]:
    """The holder masses [kg] the full grid runs for a scenario and holder."""
    if holder == "mocap":
        return (1.0,)
    return SPAN_MASSES if scenario == "span" else MASSES


def grid(quick: bool = False, **fields) -> list[Case]:
    """The sweep: every scenario x holder x MASSES x pin/clamp x DTS at the defaults, and the
    corners E in {1e5, 1e10} Pa x n in {20, 100} at 1 kg, dt 1e-2, pin and clamp, for
    CORNER_SCENARIOS (edge and lift judge a flexible cable's shape); a mocap cart (the reference: no
    holder dofs) at one mass; span up to 100 kg (SPAN_MASSES). quick: 3 per
    scenario x holder (36), light, unit and heavy holders at the three steps. ``fields``:
    Case fields set on every case (e.g. strain_limit=math.inf, to probe)."""
    pairs = [(s, h) for s, hs in SCENARIOS.items() for h in hs]
    if quick:
        picks = ((1e-2, "pin", 1e-2), (1.0, "clamp", 5e-3), (100.0, "pin", 1e-3))
        cases = [Case(s, h, mass=m, end=e, dt=dt) for s, h in pairs for m, e, dt in picks]
    else:
        cases = [Case(s, h, mass=m, end=e, dt=dt) for s, h in pairs for m in _masses(s, h)
                 for e in ("pin", "clamp") for dt in DTS]
        cases += [Case(s, h, end=e, dt=1e-2, young=y, n_edges=n) for s, h in pairs if s in CORNER_SCENARIOS
                  for y in (1e5, 1e10) for n in (20, 100) for e in ("pin", "clamp")]
    return [replace(c, **fields) for c in cases] if fields else cases
