"""The held-rods sweep's pieces (derods/bench/held.py): the frozen :class:`Case` of a run,
the built :class:`Scene`, the scenarios' constants, and the world every scene starts from
(MJCF of the holder bodies, the rod held at its start or end). SI units throughout."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..material import Material
from ..rod import Rod
from ..sim.world import ContactParams, World

#: Holders per scenario (the joint of the body holding the rod's start; span: its end).
SCENARIOS = {"fall": ("free", "slide"), "land": ("free",), "drag": ("slide", "mocap"), "edge": ("slide", "mocap"),
             "lift": ("slide", "mocap"), "swing": ("hinge", "ball"), "span": ("free",)}
#: Rod length [m] per scenario.
LENGTH = {"fall": 0.4, "land": 0.4, "swing": 0.4, "drag": 0.5, "edge": 0.5, "lift": 0.5, "span": 0.4}
#: Simulated time [s] per scenario.
DURATION = {"fall": 0.4, "land": 1.0, "drag": 1.0, "edge": 1.0, "lift": 1.0, "swing": 1.2, "span": 1.0}
BOX = 0.02            #: half side [m] of the holder box (fall, land)
FALL_TOL = 1e-4       #: fall: relative motion of rod and box over the rod length
DROP = 0.03           #: land: the box's bottom above the floor at the start [m]
REST_GAP = 1e-3       #: land: the box's lowest corner within this of the floor [m]
REST_SPEED = 1e-2     #: land: at rest, slower than this [m/s]
TRAVEL, RAMP = 0.3, 0.5   #: drag, edge: the servo target's travel [m] and its ramp time [s]
LIFT = 0.2            #: lift: the servo target's rise [m] (over RAMP)
TAIL_MOVE = 0.2       #: drag: the last vertex must move more than this along x [m]
CLEARANCE = 1e-3      #: carts hold the cable this far above its surface at the start [m]
SINK = 3e-5           #: a lying cable starts this far into its surface (about its resting depth) [m]
LEDGE_TOP, TABLE_TOP = 0.5, 0.2   #: tops [m] of the edge's ledge and the lift's table
LYING_SHARE = 0.1     #: lift: this share of the vertices (from the tail) must still lie (a clamp
#                       held level lifts ~85 % of the 0.5 m cable off the table at E = 1e7)
ARM, SWING_ANGLE, PIVOT = 0.1, math.radians(30.0), 1.0   #: swing: arm [m], release angle, pivot height [m]
ENERGY_RISE = 0.02    #: swing: allowed rise of the energy over the released one, plus h sqrt(g / ARM)
HEIGHT_RISE = 1e-3    #: swing: no vertex ever higher than its start by this [m]


@dataclass(frozen=True)
class Case:
    """One run. scenario, holder: see SCENARIOS; mass: the holder's [kg]; end: "pin" or
    "clamp" (the start); dt [s]; young E [Pa]; n_edges; radius [m]; density [kg/m^3];
    strain_limit: World's (None: its default; a knob for probes); mode: World's ("auto" picks
    "implicit" here; "alpha", "projection" to cross the modes); collide: fall only, the
    box collides (MuJoCo's default contype); duration [s] (None: DURATION[scenario]);
    friction: of the rod and the static geoms (None: the defaults, 1 for both); bending: the
    rod's curvature measure (:class:`derods.rod.Rod`'s, "tan" or "angle"); speculative: the
    rods' :class:`~derods.sim.world.ContactParams` ``speculative`` (margins sized by speed)."""

    scenario: str
    holder: str
    mass: float = 1.0
    end: str = "pin"
    dt: float = 1e-3
    young: float = 1e7
    n_edges: int = 32
    radius: float = 3e-3
    density: float = 1000.0
    strain_limit: float | None = None
    mode: str = "auto"
    collide: bool = False
    duration: float | None = None
    friction: float | None = None
    bending: str = "tan"
    speculative: bool | None = None

    def __post_init__(self):
        if self.holder not in SCENARIOS.get(self.scenario, ()):
            raise ValueError(f"no holder {self.holder!r} in scenario {self.scenario!r}; see SCENARIOS: {SCENARIOS}")
        if self.end not in ("pin", "clamp"):
            raise ValueError(f"end must be 'pin' or 'clamp', got {self.end!r}")

    @property
    def length(self) -> float:
        return LENGTH[self.scenario]

    @property
    def material(self) -> Material:
        return Material(young=self.young, density=self.density, radius=self.radius)

    @property
    def steps(self) -> int:
        return int(round((self.duration or DURATION[self.scenario]) / self.dt))


@dataclass
class Scene:
    """A built case: the world, its holder body id, ``before(t)`` (drives; before each step,
    t [s]), ``after()`` (records; after each step), ``judge()`` -> ({criterion: value}, [what
    failed]); ``at_end``: judge reads the final state (skipped when the run diverged)."""

    world: World
    body: int
    before: object = None
    after: object = None
    judge: object = None
    at_end: bool = True
    extra: dict = field(default_factory=dict)


def _world(case: Case, xml, x: np.ndarray, natural: bool = True, raised: float = 0.0,
           held_end: bool = False) -> tuple[World, int]:
    """World of the MJCF ``xml`` (the <worldbody> content with a body "holder", or a pair of
    it and an <actuator> block) with the rod of rest shape x [m] (n + 1, 3) held at its start,
    its held vertices (one for a pin, two for a clamp) started ``raised`` [m] higher; with
    ``held_end``, held by "holder" at its end and clamped to the world at its start."""
    body, act = (xml, "") if isinstance(xml, str) else xml
    spec = mujoco.MjSpec.from_string(f"<mujoco><worldbody>{body}</worldbody>{act}</mujoco>")
    contact = ContactParams(speculative=case.speculative)
    if case.friction is not None:
        contact = ContactParams(friction=case.friction, speculative=case.speculative)
        for g in spec.geoms:
            g.friction = [case.friction, g.friction[1], g.friction[2]]
    # The cables start SINK into what they lie on, and over the ledge as chords that cut its
    # corner, on purpose: the scene checks' "starts inside" is not news here.
    world = World(spec, dt=case.dt, mode=case.mode, strain_limit=case.strain_limit, contact=contact,
                  scene_checks=False)
    x0 = x.copy()
    x0[:1 if case.end == "pin" else 2, 2] += raised
    if held_end:
        world.add_rod(Rod(x, case.material, natural_curvature=natural, bending=case.bending), "rod", start="clamp", end=case.end,
                      end_body="holder")
    else:
        world.add_rod(Rod(x, case.material, natural_curvature=natural, bending=case.bending), "rod", start=case.end, start_body="holder",
                      x=x0 if raised else None)
    world.compile()
    return world, world.model.body("holder").id


def _f(*v) -> str:
    return " ".join(f"{float(a):.17g}" for a in v)


def _box_body(case: Case, z: float, joint: str, contact: str = "") -> str:
    return (f'<body name="holder" pos="0 0 {_f(z)}">{joint}<geom name="holder" type="box" size="{_f(BOX, BOX, BOX)}" '
            f'mass="{_f(case.mass)}"{contact}/></body>')
