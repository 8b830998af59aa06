"""MuJoCo's native rods, built from the same rod description as derods.

Backends:

* ``flex``: MuJoCo's 1D flexcomp with ``<elasticity young poisson>`` (MuJoCo's
  own discrete elastic rod; MuJoCo 3.17 bends only, 4.x also twists through
  per-edge twist joints), ``<edge equality>`` for inextensibility and
  ``<pin>`` for clamps, integrated with the ``discrete`` integrator.
* ``cable``: MuJoCo 3.x's cable plugin, in :mod:`derods.bench.cable`, which builds on
  the spec composition and the ring layout here.

Models are composed with ``mujoco.MjSpec``: the rod's own element (flexcomp
and composite are MJCF macros that MjSpec has no builder for) is written as one
XML element with ElementTree and expanded by MuJoCo's parser; options, the
scene (the same MJCF files derods uses, attached) and the ring closures are
set through the spec.

Parameter mapping (a careful user's settings; pitfalls measured in the native
rod baselines):

* length L, radius r, n edges: flexcomp ``type="direct"`` with points i L / n
  (``type="grid"`` refuses spacing <= radius), ``radius=r``; point coordinates
  written with 9 significant digits.
* density rho: total ``mass = rho pi r^2 L`` (flexcomp spreads it evenly over
  the n + 1 points, pinned ones included).
* E, G: ``young=E``, ``poisson = E / (2 G) - 1``, which flexcomp requires in
  [0, 0.5); a value outside is clipped and the record says so.
* clamp: ``<pin id="0 1"/>`` holds the whole first edge (the native clamp
  acts at s = h, not at h / 2 as in derods).
* edge equality ``solref="0.0001 1"`` (the default 0.02 lets a hanging rod
  stretch by 22 %); ``selfcollide="none"`` (the default makes permanent
  contacts once edges are shorter than 2 r).
* damping: mass-proportional, ``dof_damping = a m_vertex`` on the vertex dofs
  (implicit under ``discrete``), the same a [1/s] as derods' mass_damping.

Twisted rings for Michell's case: see the comment above :class:`FlexRing`.

Each rod class implements the harness's protocol
(:class:`derods.bench.backends.RodSimulator`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from .. import scenes, shapes
from ..sim.divergence import Diagnosis, check_mujoco


def has_flex_elasticity() -> bool:
    """True if the installed MuJoCo has 1D flex elasticity (3.17 and later)."""
    major, minor = (int(v) for v in mujoco.__version__.split(".")[:2])
    return (major, minor) >= (3, 17)


def has_flex_twist() -> bool:
    """True if the installed MuJoCo's 1D flex has per-edge twist joints (4.0 and later)."""
    return int(mujoco.__version__.split(".")[0]) >= 4


def poisson_for(young: float, shear: float) -> tuple[float, bool]:
    """flexcomp's Poisson ratio for E and G, clipped to [0, 0.4999]; (nu, clipped)."""
    nu = young / (2.0 * shear) - 1.0
    clipped = min(max(nu, 0.0), 0.4999)
    return clipped, clipped != nu


def _numbers(values, fmt: str = "{:.9g}") -> str:
    return " ".join(fmt.format(float(v)) for v in np.ravel(values))


def _macro_spec(element: ET.Element, extension: str | None = None) -> mujoco.MjSpec:
    """A spec holding one MJCF macro element (flexcomp, composite) in its worldbody,
    expanded by MuJoCo's parser (MjSpec has no builder for macros)."""
    root = ET.Element("mujoco")
    if extension:
        ET.SubElement(ET.SubElement(root, "extension"), "plugin", plugin=extension)
    ET.SubElement(root, "compiler", angle="radian")
    ET.SubElement(root, "worldbody").append(element)
    return mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))


def _compose(spec: mujoco.MjSpec, integrator, dt: float, gravity, scene: str | None) -> mujoco.MjSpec:
    """Set the spec's options and attach a scene of mjcf/ (its geoms, prefixed "scene_")."""
    spec.option.integrator = integrator
    spec.option.timestep = dt
    spec.option.gravity = np.asarray(gravity, dtype=float)
    if scene is not None:
        child = mujoco.MjSpec.from_file(str(scenes.path(scene)))
        # Only the scene's geoms matter; its own options would conflict with the rod's.
        child.option.integrator, child.option.timestep = integrator, dt
        spec.attach(child, frame=spec.worldbody.add_frame(), prefix="scene_")
    return spec


def flex_spec(points: np.ndarray, radius: float, mass: float, young: float, poisson: float,
              closed: bool = False, pinned=(), dt: float = 1e-2, gravity=(0.0, 0.0, -9.81),
              scene: str | None = None, contact_solref=(0.005, 1.0), holder: str | None = None) -> mujoco.MjSpec:
    """One flexcomp rod (named "rod") through ``points`` [m] (n + 1, 3), in a scene of mjcf/.

    holder: the name of a body (without joints, at the origin) to put the flexcomp in, so
    that its pinned points belong to that body (and ride on whatever it is attached to);
    None: the world holds them."""
    n = len(points) if closed else len(points) - 1
    elem = np.column_stack([np.arange(n), (np.arange(n) + 1) % len(points)])
    flex = ET.Element("flexcomp", name="rod", type="direct", dim="1", point=_numbers(points),
                      element=" ".join(str(int(i)) for i in elem.ravel()), radius=repr(float(radius)),
                      mass=repr(float(mass)), rgba="0.2 0.6 0.85 1")
    if len(pinned):
        ET.SubElement(flex, "pin", id=" ".join(str(i) for i in pinned))
    ET.SubElement(flex, "edge", equality="true", solref="0.0001 1")
    ET.SubElement(flex, "contact", selfcollide="none", condim="3", solref=_numbers(contact_solref, "{!r}"))
    ET.SubElement(flex, "elasticity", young=repr(float(young)), poisson=repr(float(poisson)), damping="0")
    if holder is not None:
        body = ET.Element("body", name=holder)
        body.append(flex)
        flex = body
    return _compose(_macro_spec(flex), mujoco.mjtIntegrator.mjINT_DISCRETE, dt, gravity, scene)


class CheckedSteps:
    """mj_step on a native model, each step checked as derods checks its own
    (:func:`derods.sim.divergence.check_mujoco`: a MuJoCo reset, or a dof of ``dofs`` not
    finite or too fast, raises :class:`derods.sim.divergence.DivergenceError` naming
    ``label``); n_steps counts the steps made."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, dofs: np.ndarray, label: str):
        self.model, self.data, self.dofs = model, data, dofs
        self.n_steps = 0
        self._badqacc = 0
        self._diagnosis = Diagnosis([label])

    def step(self) -> None:
        mujoco.mj_step(self.model, self.data)
        self.n_steps += 1
        self._badqacc = check_mujoco(self.data, self.dofs, self._badqacc, self._diagnosis, self.n_steps)


class NativeRod:
    """A native MuJoCo rod (one flexcomp) in its own model; the harness's protocol
    (:class:`derods.bench.backends.RodSimulator`). ``rod`` arguments are accepted and
    ignored: the model holds one rod."""

    def __init__(self, model: mujoco.MjModel, mass_damping: float = 0.0):
        self.model = model
        self.data = mujoco.MjData(self.model)
        m = self.model
        adr, num = m.flex_vertadr[0], m.flex_vertnum[0]
        self.body_ids = m.flex_vertbodyid[adr:adr + num]
        self.free = np.array([m.body_dofnum[b] > 0 for b in self.body_ids])
        self._dofs = np.concatenate([m.body_dofadr[b] + np.arange(3) for b in self.body_ids[self.free]])
        if mass_damping:
            for b in self.body_ids[self.free]:
                m.dof_damping[m.body_dofadr[b]:m.body_dofadr[b] + 3] = mass_damping * m.body_mass[b]
        self._steps = CheckedSteps(m, self.data, self._dofs, self.label)
        mujoco.mj_forward(m, self.data)

    label = "native flex"
    active_terms = {"rod": ("native",)}

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def n_steps(self) -> int:
        return self._steps.n_steps

    def dofs(self, rod=0) -> np.ndarray:
        """MuJoCo dofs that carry the rod."""
        return self._dofs

    def vertex_body(self, rod, vertex: int) -> int:
        """MuJoCo body id of a vertex (for xfrc_applied)."""
        return int(self.body_ids[vertex])

    def positions(self, rod=0) -> np.ndarray:
        # flexvert_xpos covers pinned vertices too (their "body" is the world).
        adr, num = self.model.flex_vertadr[0], self.model.flex_vertnum[0]
        return self.data.flexvert_xpos[adr:adr + num].copy()

    def velocities(self, rod=0) -> np.ndarray:
        v = np.zeros((len(self.body_ids), 3))
        v[self.free] = self.data.qvel[self._dofs].reshape(-1, 3)
        return v

    def set_positions(self, rod, x: np.ndarray) -> None:
        m, d = self.model, self.data
        for i, b in enumerate(self.body_ids):
            if self.free[i]:
                jnt = m.body_jntadr[b]
                d.qpos[m.jnt_qposadr[jnt]:m.jnt_qposadr[jnt] + 3] = x[i] - m.body_pos[b]
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)

    def set_velocities(self, rod, v: np.ndarray) -> None:
        self.data.qvel[self._dofs] = np.asarray(v, dtype=float)[self.free].ravel()

    def step(self, n_steps: int = 1) -> None:
        for _ in range(n_steps):
            self._steps.step()


def flex_rod(points: np.ndarray, p, pinned=(), gravity=None, closed: bool = False, scene: str | None = None,
             mass_damping: float = 0.0) -> tuple[NativeRod, dict]:
    """A native flexcomp rod for the benchmark parameters ``p`` (:class:`derods.bench.CaseParams`).

    Returns the rod and the mapping notes (e.g. a clipped Poisson ratio).
    """
    mat = p.material
    nu, clipped = poisson_for(mat.young, mat.shear_modulus)
    mass = mat.density * math.pi * mat.radius**2 * p.length
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    spec = flex_spec(points, mat.radius, mass, mat.young, nu, closed, pinned, p.dt, grav, scene)
    return NativeRod(spec.compile(), mass_damping), {"poisson": nu, "poisson_clipped": clipped}


def flex_world(rods: list[np.ndarray], p, pinned=(), gravity=None, scene: str | None = None,
               mass_damping: float = 0.0, friction: float | None = None,
               memory: int | None = None) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Several flexcomp rods (points [m], each (n_i + 1, 3)) in one model, set up as
    :func:`flex_rod` sets up one (rod i's names prefixed "r<i>_"). For timing many rods
    against derods; returns the compiled model and its data. friction: the rods' sliding
    friction coefficient (None: MuJoCo's default, 1); memory: MuJoCo's arena [bytes] (None:
    MuJoCo's own guess, too small for a heap of many rods' contacts)."""
    mat = p.material
    nu, _ = poisson_for(mat.young, mat.shear_modulus)
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    spec = _compose(mujoco.MjSpec(), mujoco.mjtIntegrator.mjINT_DISCRETE, p.dt, grav, scene)
    for i, points in enumerate(rods):
        length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
        mass = mat.density * math.pi * mat.radius**2 * length
        child = flex_spec(points, mat.radius, mass, mat.young, nu, pinned=pinned, dt=p.dt, gravity=grav)
        spec.attach(child, frame=spec.worldbody.add_frame(), prefix=f"r{i}_")
    if friction is not None:
        for flex in spec.flexes:
            flex.friction = [float(friction), 0.005, 0.0001]
    if memory is not None:
        spec.memory = int(memory)
    model = spec.compile()
    if mass_damping:
        for b in range(model.nbody):
            if model.body_dofnum[b] == 3 and model.jnt_type[model.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_SLIDE:
                model.dof_damping[model.body_dofadr[b]:model.body_dofadr[b] + 3] = mass_damping * model.body_mass[b]
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


# --- Twisted rings (the ``michell`` case) -------------------------------------------------------
#
# Neither native rod closes a naturally straight ring with an imposed twist by itself: both take
# their rest shape from the shape they are built in, a closed flex loop has no twist state (its
# torsion is the dihedral angle of osculating planes) and the composite cable is open. Both rings
# are therefore built as an open rod of n + 1 edges laid around the circle whose last edge lies on
# its first: the first edge is clamped, the last is held on it by equality constraints with its
# material frame turned by the total twist Theta. Every vertex of the ring then carries its bending
# and twist. The clamp removes only the ring's rigid motions, so Michell's threshold is unchanged:
# a rigid motion adds no energy, and any buckling mode of the free ring, less the rigid motion that
# brings its clamped edge back, is a mode of the clamped ring with the same energy.

#: Closing constraints: time constant 2 dt (the stiffest MuJoCo allows without disabling its
#: reference-safety clamp) and impedance 0.9999 (the default 0.9 - 0.95 lets a cable ring open by
#: 2.5 cm at n = 30, E = 1e8 Pa, dt = 1e-3 s).
CLOSURE_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)


def _stiff(eq, dt: float) -> None:
    eq.solref = [2.0 * dt, 1.0]
    eq.solimp = list(CLOSURE_SOLIMP)


def ring_vertices(p) -> np.ndarray:
    """The twisted ring's rest vertices [m], (n, 3), for benchmark parameters ``p``: circumference
    ``p.length`` about the origin in the xy plane, starting on +y (:func:`shapes.circle`)."""
    return shapes.circle(p.length / (2.0 * math.pi), p.n_edges)


def _ring_layout(rest: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The n + 2 points of a native ring placed at ``x`` (n, 3) [m]: x with its first edge
    kept at rest (it is clamped), then that edge again (the closing edge)."""
    x = np.asarray(x, dtype=float)
    if x.shape != rest.shape:
        raise ValueError(f"x must have shape {rest.shape}, one row per ring vertex, got {x.shape}")
    return np.concatenate([rest[:2], x[2:], rest[:2]])


class FlexRing(NativeRod):
    """A naturally straight flexcomp ring with total twist (see the comment above).

    Its n + 2 points lie on a straight line in ``qpos0`` (so MuJoCo keeps no rest curvature)
    and are set around the circle through ``qpos``; points 0, 1 are pinned, points n, n + 1
    held on them by joint equalities, and the last edge's twist joint by a joint equality
    at Theta. ``positions`` and ``set_positions`` see the n ring vertices only.
    """

    def __init__(self, model: mujoco.MjModel, rest: np.ndarray, total_twist: float):
        super().__init__(model)
        self.rest = np.asarray(rest, dtype=float)
        self.total_twist = float(total_twist)
        n = len(self.rest)
        # Edge k's twist angle: rod_twist_k, the last edge's rod_twist; the clamped edge 0 has none.
        names = [f"rod_twist_{k}" for k in range(1, n)] + ["rod_twist"]
        self._twist_qpos = np.array([model.joint(nm).qposadr[0] for nm in names])
        self.set_positions(0, self.rest)

    def positions(self, rod=0) -> np.ndarray:
        return super().positions()[:len(self.rest)]

    def velocities(self, rod=0) -> np.ndarray:
        return super().velocities()[:len(self.rest)]

    def set_positions(self, rod, x: np.ndarray) -> None:
        """Place the ring at ``x`` (n, 3) [m] at rest, twisted evenly; x's first two rows
        (the clamped edge) are ignored."""
        n = len(self.rest)
        super().set_positions(rod, _ring_layout(self.rest, x))
        self.data.qpos[self._twist_qpos] = self.total_twist * np.arange(1, n + 1) / n
        mujoco.mj_forward(self.model, self.data)


def flex_ring(p, total_twist: float) -> FlexRing:
    """A naturally straight flexcomp ring of circumference ``p.length`` with total twist
    ``total_twist`` [rad], without gravity, for the benchmark parameters ``p``."""
    if not has_flex_twist():
        raise ValueError(f"a twisted flex ring needs MuJoCo >= 4.0 (per-edge twist joints); this is "
                         f"{mujoco.__version__}: pip install -U mujoco")
    mat = p.material
    n = p.n_edges
    rest = ring_vertices(p)
    h = float(np.linalg.norm(rest[1] - rest[0]))
    line = rest[0] + np.arange(n + 2)[:, None] * (rest[1] - rest[0])  # straight, edge length h
    nu, _ = poisson_for(mat.young, mat.shear_modulus)
    mass = mat.density * math.pi * mat.radius**2 * h * (n + 2)  # rho A h per point
    spec = flex_spec(line, mat.radius, mass, mat.young, nu, pinned=(0, 1), dt=p.dt, gravity=(0.0, 0.0, 0.0))
    for i, target in ((n, rest[0]), (n + 1, rest[1])):
        for axis, joint in enumerate(spec.body(f"rod_{i}").joints):  # three slides along x, y, z
            joint.name = f"close_{i}_{axis}"
            eq = spec.add_equality(name=joint.name, type=mujoco.mjtEq.mjEQ_JOINT, name1=joint.name)
            eq.data[0] = target[axis] - line[i, axis]
            _stiff(eq, p.dt)
    eq = spec.add_equality(name="ring_twist", type=mujoco.mjtEq.mjEQ_JOINT, name1="rod_twist")
    eq.data[0] = total_twist
    _stiff(eq, p.dt)
    return FlexRing(spec.compile(), rest, total_twist)
