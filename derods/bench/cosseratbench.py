"""derods as a solver of cosseratbench, an independent benchmark suite of rods and ropes.

cosseratbench (on the package registry) describes each experiment in physical terms
only (:class:`cosseratbench.Scenario`: rods, their ends, loads, gravity, fixed
cylinders and planes) and leaves the numerics to each solver's adapter. This is
derods' adapter, registered as the entry point ``derods`` of the group
``cosseratbench.solvers``: ``cosseratbench run -s derods``. It goes through derods'
public API only: :class:`derods.World`, :class:`derods.Rod`, :class:`derods.Material`,
:class:`derods.ContactParams`, ends held by the world or by scene bodies, and
``data.xfrc_applied`` for point loads.

Numerics, the same for every experiment (see :meth:`DerodsSolver.settings`):

- the step: generalized-alpha (``mode="alpha"``, second order, keeps a resolved
  swing's amplitude) at the largest step of at most ``MAX_TIME_STEP`` that divides the
  frame interval;
- damping: none when the dynamics are the result; a drag at twice the scenario's
  slowest angular frequency (critical for its slowest mode) when equilibrium is,
  the rule the suite's own adapters follow;
- stretch: the rod's own axial stiffness E A (the catenary sags deeper by it);
  derods' rods do not shear;
- contact: MuJoCo's detection, derods' implicit contact solve; Coulomb friction, the
  larger coefficient of the two things touching (MuJoCo's rule, the suite's too), in
  elliptic cones (Coulomb's law as the scenarios state it: a pyramid's soft rows spend
  normal force across the slide, and a rope over a capstan at 0.95 of its holding
  overhang slid off), with static friction on (``ContactParams(static_friction=True)``:
  resting contacts anchored, so a rope below its friction limit holds instead of
  creeping).

Discretization. A discrete clamp holds a whole edge and acts where that edge's
material frame sits, at its middle (:func:`derods.shapes.cantilever`); so a clamped
end's edge reaches h/2 past the end, and the rod's n edges span the rest. The suite
reads n + 1 nodes evenly spaced along the unstretched rod: they are interpolated
between derods' vertices (exactly the vertices where no end is clamped).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

try:
    from cosseratbench import Capability, Diverged, Trajectory
    from cosseratbench.scenario import Cylinder, End, EndCondition, Motion, Plane, Rod, Scenario
except ImportError as err:  # pragma: no cover - only without the extra
    raise ImportError("derods' cosseratbench adapter needs the suite: pip install 'derods[cosseratbench]'",
                      name="cosseratbench") from err

import derods
from derods import ContactParams, DivergenceError, World

#: The longest time step [s] the adapter takes: the frame interval is split into
#: equal steps of at most this (times the suite's ``time_step_scale`` option).
MAX_TIME_STEP = 1e-3
#: The mode of every run (:data:`derods.MODES`).
MODE = "alpha"
#: The MuJoCo integrator of the scene (derods' implicit steps need implicitfast or Euler).
INTEGRATOR = "implicitfast"
#: MuJoCo's friction cone.
CONE = mujoco.mjtCone.mjCONE_ELLIPTIC
#: Contact: MuJoCo's soft-constraint time constant in time steps, and its impedance.
CONTACT_TIME_STEPS = 5.0
CONTACT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
#: Speculative contact margin, in radii of the thinnest rod (0: contacts once touching).
CONTACT_MARGIN_RADII = 0.0

_ENDS = {EndCondition.FREE: "free", EndCondition.PINNED: "pin", EndCondition.CLAMPED: "clamp"}


def _source_digest() -> str:
    """A short digest of derods' Python sources: the suite reuses a saved run while the
    solver's version is unchanged, and derods' physics changes between its releases."""
    root = Path(derods.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:12]


@dataclass(frozen=True)
class Discretization:
    """How a rod of the suite becomes a derods rod of n edges, and how derods' vertices
    are read back as the suite's n + 1 nodes.

    sigma: unstretched arc length [m] of each derods vertex from the rod's start,
        shape (n + 1,); below 0 and above L where an end is clamped (half an edge).
    x0: initial vertex positions [m], shape (n + 1, 3), on the scenario's centerline
        (continued straight past a clamped end).
    node_vertex, node_weight: node j of the suite sits at (1 - w) x[k] + w x[k + 1],
        k = node_vertex[j], w = node_weight[j]; shapes (n + 1,).
    element_edge: the derods edge whose material frame is element j's, shape (n,).
    """

    sigma: np.ndarray
    x0: np.ndarray
    node_vertex: np.ndarray
    node_weight: np.ndarray
    element_edge: np.ndarray

    @classmethod
    def of(cls, rod: Rod, n_elements: int) -> Discretization:
        n, length = int(n_elements), rod.length
        clamped = [rod.condition(end) is EndCondition.CLAMPED for end in (End.START, End.END)]
        n_clamped = sum(clamped)
        if n - 0.5 * n_clamped < 1:
            raise NotImplementedError(f"derods needs at least {1 + n_clamped} edges for this rod, "
                                      f"asked for {n}")
        h = length / (n - 0.5 * n_clamped)
        sigma = (-0.5 * h if clamped[0] else 0.0) + h * np.arange(n + 1)
        x0 = _along_centerline(rod, sigma)
        s_nodes = np.linspace(0.0, length, n + 1)
        k = np.clip(np.searchsorted(sigma, s_nodes, side="right") - 1, 0, n - 1)
        w = (s_nodes - sigma[k]) / h
        mid = 0.5 * (s_nodes[1:] + s_nodes[:-1])
        edge = np.clip(np.searchsorted(sigma, mid, side="right") - 1, 0, n - 1)
        return cls(sigma, x0, k, w, edge)

    @property
    def rest_lengths(self) -> np.ndarray:
        """Unstretched edge lengths [m], shape (n,)."""
        return np.diff(self.sigma)

    def nodes(self, x: np.ndarray) -> np.ndarray:
        """The suite's nodes [m], shape (n + 1, 3), from derods' vertices x, shape (n + 1, 3)."""
        k, w = self.node_vertex, self.node_weight[:, None]
        return (1.0 - w) * x[k] + w * x[k + 1]

    def directors(self, nodes: np.ndarray, m1: np.ndarray) -> np.ndarray:
        """The suite's element directors, shape (n, 3): each element's derods material
        director m1 (shape (n, 3) per edge), made perpendicular to the element."""
        t = np.diff(nodes, axis=0)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        d = m1[self.element_edge]
        d = d - np.einsum("ij,ij->i", d, t)[:, None] * t
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def _along_centerline(rod: Rod, s: np.ndarray) -> np.ndarray:
    """Points [m] at unstretched arc lengths ``s`` along the rod's initial centerline,
    shape (len(s), 3); beyond its ends, straight on along its first or last segment."""
    points = np.asarray(rod.centerline, dtype=float)
    if rod.rest_arc_length is not None:
        arc = np.asarray(rod.rest_arc_length, dtype=float)
    else:
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    out = np.stack([np.interp(s, arc, points[:, axis]) for axis in range(3)], axis=1)
    before, after = s < 0.0, s > arc[-1]
    out[before] = points[0] + np.outer(s[before] / arc[1], points[1] - points[0])
    out[after] = points[-1] + np.outer((s[after] - arc[-1]) / (arc[-1] - arc[-2]), points[-1] - points[-2])
    return out


def _quat(rotation: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(rotation, dtype=float).ravel())
    return q


def _z_to(normal: np.ndarray) -> np.ndarray:
    """The quaternion turning +z onto ``normal`` (a plane geom collides on its +z side)."""
    q = np.zeros(4)
    mujoco.mju_quatZ2Vec(q, np.asarray(normal, dtype=float))
    return q


def contact_params(scenario: Scenario, dt: float) -> ContactParams:
    """Contact for every rod of a scenario: frictionless rows where nothing has
    friction, self-contact where the scenario says a rod can reach itself, at any
    resolution (a world leaves out a rod's self-contacts nearer along it than pi r,
    :func:`derods.sim.exclusion.self_reach`: the twist at n = 100, edges 1 cm of radius
    1 cm, does not touch its edges two apart at rest). (Each rod's own coefficient is
    set on its flex once built: MuJoCo takes the larger of the two things touching,
    the suite's rule.)"""
    friction = max([r.friction for r in scenario.rods] + [0.0])
    any_friction = friction > 0 or any(o.friction > 0 for o in scenario.obstacles)
    return ContactParams(friction=friction, condim=3 if any_friction else 1,
                         solref=(CONTACT_TIME_STEPS * dt, 1.0), solimp=CONTACT_SOLIMP,
                         self_collision=bool(scenario.self_contact), rod_rod=True,
                         margin=CONTACT_MARGIN_RADII * min(r.radius for r in scenario.rods),
                         static_friction=True)


class DerodsSolver:
    """cosseratbench's solver protocol for derods (``cosseratbench.Solver``)."""

    name = "derods"
    backend_version = f"derods {derods.__version__}+{_source_digest()}, mujoco {mujoco.__version__}"
    # Rods stretch (E A), touch each other and themselves with friction, and touch any
    # MuJoCo geom; they do not shear.
    capabilities = frozenset({Capability.STRETCH, Capability.ROD_CONTACT, Capability.ROD_FRICTION,
                              Capability.CYLINDER_CONTACT, Capability.PLANE_CONTACT})

    def __init__(self, time_step_scale: float = 1.0) -> None:
        if not time_step_scale > 0:
            raise ValueError(f"time_step_scale must be > 0, got {time_step_scale!r}")
        self.max_time_step = MAX_TIME_STEP * float(time_step_scale)

    # -- numerics ------------------------------------------------------------
    def _steps(self, scenario: Scenario, n_frames: int) -> tuple[float, int]:
        """The time step [s], and how many make one frame."""
        interval = scenario.duration / (n_frames - 1)
        per_frame = max(1, math.ceil(interval / self.max_time_step * (1 - 1e-12)))
        return interval / per_frame, per_frame

    @staticmethod
    def _damping(scenario: Scenario) -> float:
        return 2.0 * scenario.slowest_frequency() if scenario.quasi_static else 0.0

    def settings(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> dict:
        """The numerical choices made for a scenario, as JSON values."""
        dt, _ = self._steps(scenario, n_frames)
        contact = contact_params(scenario, dt)
        return {
            "mode": MODE,
            "time_step": dt,
            "integrator": INTEGRATOR,
            "mass_damping": self._damping(scenario),
            "stretch_stiffness": "E A",
            "clamp": "edge held, its middle at the end",
            "friction_cone": "elliptic",
            "contact_solref": list(contact.solref),
            "contact_solimp": list(contact.solimp),
            "contact_margin": contact.margin,
            "static_friction": contact.static_friction,
            "self_contact": contact.self_collision,
        }

    # -- the run -------------------------------------------------------------
    def build(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> Built:
        """The compiled derods world of a scenario, ready to step (see :class:`Built`)."""
        dt, _ = self._steps(scenario, n_frames)
        spec = mujoco.MjSpec()
        spec.option.cone = CONE
        for obstacle in scenario.obstacles:
            _add_obstacle(spec, obstacle)
        entries, driven = [], []
        for i, rod in enumerate(scenario.rods):
            disc = Discretization.of(rod, n_elements)
            holders = {}
            for end in End:
                motion = rod.motion(end)
                if motion is None:
                    continue
                point = np.asarray(rod.centerline[0 if end is End.START else -1], dtype=float)
                mocap, holder = _add_driver(spec, f"r{i}_{end.value}", point, motion,
                                            rod.material.density * rod.area * rod.length / n_elements)
                holders[end] = holder
                driven.append((mocap, point, motion))
            entries.append((rod, disc, holders))
        world = World(spec, dt=dt, gravity=scenario.gravity, mode=MODE, integrator=INTEGRATOR,
                      mass_damping=self._damping(scenario), contact=contact_params(scenario, dt))
        for i, (rod, disc, holders) in enumerate(entries):
            world.add_rod(_derods_rod(rod, disc), f"r{i}", x=disc.x0,
                          start=_ENDS[rod.start], end=_ENDS[rod.end],
                          start_body=holders.get(End.START), end_body=holders.get(End.END))
        model = world.model
        for i, (rod, _, _) in enumerate(entries):
            # Each rod's own coefficient: MuJoCo takes the larger of the two things touching.
            model.flex_friction[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, f"r{i}"), 0] = rod.friction
            for load in rod.loads:
                _apply_load(world, i, entries[i], load)
        mocaps = [(int(model.body(name).mocapid[0]), point, motion) for name, point, motion in driven]
        return Built(world, tuple(disc for _, disc, _ in entries), tuple(mocaps))

    def run(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> Trajectory:
        dt, per_frame = self._steps(scenario, n_frames)
        built = self.build(scenario, n_elements=n_elements, n_frames=n_frames)
        world, data = built.world, built.world.data
        x, d = built.frame()
        xs, ds = [[p] for p in x], [[q] for q in d]
        for f in range(n_frames - 1):
            for _ in range(per_frame):
                for mocap, point, motion in built.mocaps:
                    displacement, rotation = motion.pose(data.time + dt)
                    data.mocap_pos[mocap] = point + displacement
                    data.mocap_quat[mocap] = _quat(rotation)
                try:
                    world.step()
                except DivergenceError as err:
                    raise Diverged(str(err), time=float(data.time)) from None
            x, d = built.frame()
            for history, p in zip(xs, x):
                history.append(p)
            for history, q in zip(ds, d):
                history.append(q)
        return Trajectory(np.linspace(0.0, scenario.duration, n_frames),
                          tuple(np.stack(h) for h in xs), tuple(np.stack(h) for h in ds))


@dataclass(frozen=True)
class Built:
    """A scenario as a derods world: the :class:`derods.World` (rod i named ``f"r{i}"``),
    each rod's :class:`Discretization`, and the driven clamps as (MuJoCo mocap id, the
    end's starting point [m], its :class:`cosseratbench.Motion`)."""

    world: World
    discretizations: tuple
    mocaps: tuple

    def frame(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Each rod's nodes [m], shape (n + 1, 3), and element directors, shape (n, 3), now."""
        nodes, directors = [], []
        for i, disc in enumerate(self.discretizations):
            state = self.world.rod_state(i)
            m1, _ = derods.frames.material_frames(state.u, state.t, state.theta)
            x = disc.nodes(self.world.positions(i))
            nodes.append(x)
            directors.append(disc.directors(x, m1))
        return nodes, directors


def _derods_rod(rod: Rod, disc: Discretization) -> derods.Rod:
    """The derods rod: naturally straight, its rest edges the unstretched ones, E and G
    of the scenario, stretch stiffness E A, its first reference director the
    scenario's ``normal`` (so the material frame starts as the suite's directors)."""
    m = rod.material
    material = derods.Material(young=m.youngs_modulus, shear=m.shear_modulus, density=m.density,
                               radius=rod.radius)
    first = disc.x0[1] - disc.x0[0]
    rest_x = disc.sigma[:, None] * (first / np.linalg.norm(first))
    return derods.Rod(rest_x, material, stretch_stiffness=material.stretch_stiffness,
                      u0=np.asarray(rod.normal, dtype=float))


def _add_obstacle(spec: mujoco.MjSpec, obstacle) -> None:
    geom = spec.worldbody.add_geom()
    geom.friction = [float(obstacle.friction), 0.0, 0.0]
    geom.condim = 3
    if isinstance(obstacle, Plane):
        geom.type = mujoco.mjtGeom.mjGEOM_PLANE
        geom.pos = list(map(float, obstacle.point))
        geom.quat = _z_to(obstacle.unit_normal)
        geom.size = [0.0, 0.0, 1.0]
    elif isinstance(obstacle, Cylinder):
        half = obstacle.unit_axis * obstacle.length / 2.0
        center = np.asarray(obstacle.center, dtype=float)
        geom.type = mujoco.mjtGeom.mjGEOM_CYLINDER
        geom.fromto = np.concatenate([center - half, center + half])
        geom.size = [float(obstacle.radius), 0.0, 0.0]
    else:
        raise NotImplementedError(f"derods' adapter knows planes and cylinders, not {type(obstacle).__name__}")


def _add_driver(spec: mujoco.MjSpec, name: str, point: np.ndarray, motion: Motion,
                carriage_mass: float) -> tuple[str, str]:
    """A mocap body at a driven clamp's starting point, moved by the motion; with
    ``slides_along``, a carriage on a slide joint inside it that holds the end, the
    mass of one element. Returns the mocap body's name and the holder's."""
    body = spec.worldbody.add_body()
    body.name = f"{name}_clamp"
    body.mocap = True
    body.pos = list(map(float, point))
    if motion.slides_along is None:
        return body.name, body.name
    carriage = body.add_body()
    carriage.name = f"{name}_carriage"
    carriage.mass = carriage_mass
    carriage.inertia = [carriage_mass * 1e-6] * 3
    carriage.explicitinertial = True
    joint = carriage.add_joint()
    joint.type = mujoco.mjtJoint.mjJNT_SLIDE
    joint.axis = list(map(float, motion.axis))
    return body.name, carriage.name


def _apply_load(world: World, i: int, entry, load) -> None:
    """A constant point load on an end: on its last vertex if free or pinned there, on
    the carriage if a sliding clamp holds it; a clamp on the world or on a mocap body
    takes it itself."""
    rod, disc, holders = entry
    end = load.at
    if rod.condition(end) is EndCondition.CLAMPED:
        holder = holders.get(end)
        if holder is None or not holder.endswith("_carriage"):
            return
        body = world.model.body(holder).id
    else:
        if rod.condition(end) is EndCondition.PINNED:
            return
        body = world.vertex_body(i, 0 if end is End.START else -1)
    world.data.xfrc_applied[body, :3] += np.asarray(load.force, dtype=float)
