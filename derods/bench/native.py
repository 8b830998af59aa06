"""MuJoCo's native rods, built from the same rod description as derods.

Backends:

* ``flex``: MuJoCo's 1D flexcomp with ``<elasticity young poisson>`` (MuJoCo's
  own discrete elastic rod; MuJoCo 3.17 bends only, 4.x also twists through
  per-edge twist joints), ``<edge equality>`` for inextensibility and
  ``<pin>`` for clamps, integrated with the ``discrete`` integrator.
* ``cable``: MuJoCo 3.x's cable plugin (``mujoco.elasticity.cable`` on a
  ``<composite type="cable">``); MuJoCo 4.0 removed it, so it runs only in an
  environment with mujoco 3.17 (see the README for the one command that makes it).

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

The cable (:func:`cable_spec`): the same vertices as an explicit ``vertex``
list, ``bend=E``, ``twist=G``, ``flat="true"`` (naturally straight), geom mass
rho A h per segment, no self-collision, ``initial="none"`` for a clamp, joint damping 0.01 E I / h,
``implicitfast``. Twisted rings for Michell's case: see the comment above
:class:`FlexRing`.

Each rod class implements the harness's protocol
(:class:`derods.bench.backends.RodSimulator`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from .. import frames, scenes, shapes
from ..sim.divergence import Diagnosis, check_mujoco



def has_flex_elasticity() -> bool:
    """True if the installed MuJoCo has 1D flex elasticity (3.17 and later)."""
    major, minor = (int(v) for v in mujoco.__version__.split(".")[:2])
    return (major, minor) >= (3, 17)


def has_flex_twist() -> bool:
    """True if the installed MuJoCo's 1D flex has per-edge twist joints (4.0 and later)."""
    return int(mujoco.__version__.split(".")[0]) >= 4


def has_cable() -> bool:
    """True if the installed MuJoCo still ships the cable plugin (3.x)."""
    return int(mujoco.__version__.split(".")[0]) < 4


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
        self.n_steps = 0
        self._badqacc = 0
        self._diagnosis = Diagnosis([self.label])
        mujoco.mj_forward(m, self.data)

    label = "native flex"
    active_terms = {"rod": ("native",)}

    @property
    def time(self) -> float:
        return float(self.data.time)

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
            mujoco.mj_step(self.model, self.data)
            self.n_steps += 1
            self._badqacc = check_mujoco(self.data, self._dofs, self._badqacc, self._diagnosis, self.n_steps)


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
               mass_damping: float = 0.0) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Several flexcomp rods (points [m], each (n_i + 1, 3)) in one model, set up as
    :func:`flex_rod` sets up one (rod i's names prefixed "r<i>_"). For timing many rods
    against derods; returns the compiled model and its data."""
    mat = p.material
    nu, _ = poisson_for(mat.young, mat.shear_modulus)
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    spec = _compose(mujoco.MjSpec(), mujoco.mjtIntegrator.mjINT_DISCRETE, p.dt, grav, scene)
    for i, points in enumerate(rods):
        length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
        mass = mat.density * math.pi * mat.radius**2 * length
        child = flex_spec(points, mat.radius, mass, mat.young, nu, pinned=pinned, dt=p.dt, gravity=grav)
        spec.attach(child, frame=spec.worldbody.add_frame(), prefix=f"r{i}_")
    model = spec.compile()
    if mass_damping:
        for b in range(model.nbody):
            if model.body_dofnum[b] == 3 and model.jnt_type[model.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_SLIDE:
                model.dof_damping[model.body_dofadr[b]:model.body_dofadr[b] + 3] = mass_damping * model.body_mass[b]
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def cable_spec(vertices: np.ndarray, radius: float, density: float, young: float, shear: float,
               clamped: bool = True, dt: float = 1e-2, gravity=(0.0, 0.0, -9.81), joint_damping: float = 0.0,
               scene: str | None = None) -> mujoco.MjSpec:
    """A MuJoCo 3.x cable (``<composite type="cable">`` with the elasticity plugin).

    vertices: (n + 1, 3) [m], equally spaced; one segment body per edge.
    ``geom mass = rho A h`` per segment (the default density would add the capsules'
    end caps: 3.7x too heavy at n = 200); ``initial="none"`` welds the first segment
    (the clamp), ``"free"`` gives it a free joint; joint damping [N m s] on the ball
    joints, implicit in MuJoCo's integrators. ``flat="true"``: the rod is naturally
    straight whatever shape it starts in (as every benchmark rod is). ``contype="2"
    conaffinity="1"``: the segments touch the scene (default geoms: 1, 1) but not each
    other, like the flexcomp's ``selfcollide="none"`` (with self-contact, a cable curled
    into a circle by an end couple diverges at 0.47 s when its tip meets its clamp;
    without, it closes to 2e-6 L at n = 20).
    """
    vertices = np.asarray(vertices, dtype=float)
    h = float(np.linalg.norm(vertices[1] - vertices[0]))
    seg_mass = density * math.pi * radius**2 * h
    comp = ET.Element("composite", prefix="c", type="cable", vertex=_numbers(vertices, "{:.12g}"),
                      initial="none" if clamped else "free")
    plugin = ET.SubElement(comp, "plugin", plugin="mujoco.elasticity.cable")
    for key, value in (("twist", repr(float(shear))), ("bend", repr(float(young))), ("vmax", "0"), ("flat", "true")):
        ET.SubElement(plugin, "config", key=key, value=value)
    ET.SubElement(comp, "joint", kind="main", damping=repr(float(joint_damping)))
    ET.SubElement(comp, "geom", type="capsule", size=repr(float(radius)), mass=repr(float(seg_mass)),
                  rgba="0.85 0.55 0.2 1", condim="3", contype="2", conaffinity="1")
    spec = _macro_spec(comp, extension="mujoco.elasticity.cable")
    return _compose(spec, mujoco.mjtIntegrator.mjINT_IMPLICITFAST, dt, gravity, scene)


class CableRod(NativeRod):
    """A MuJoCo 3.x cable; the harness's protocol.

    Vertices are the segment bodies' origins plus the tip site; velocities are the
    linear velocities of those points. The cable's dofs are its joints (a free or
    welded root and ball joints), not vertex positions.
    """

    label = "native cable"

    def __init__(self, model: mujoco.MjModel):
        self.model = model
        self.data = mujoco.MjData(self.model)
        m = self.model
        names = [m.body(i).name for i in range(m.nbody)]
        self.body_ids = np.array([i for i, nm in enumerate(names) if nm.startswith("cB_")])
        self.tip_site = m.site("cS_last").id
        self._dofs = np.arange(m.nv)
        self.free = np.ones(len(self.body_ids) + 1, dtype=bool)
        self.n_steps = 0
        self._badqacc = 0
        self._diagnosis = Diagnosis([self.label])
        mujoco.mj_forward(m, self.data)

    def vertex_body(self, rod, vertex: int) -> int:
        """The segment body that starts at a vertex (the last segment for the tip)."""
        return int(self.body_ids[min(vertex, len(self.body_ids) - 1)])

    def positions(self, rod=0) -> np.ndarray:
        return np.concatenate([self.data.xpos[self.body_ids], self.data.site_xpos[[self.tip_site]]])

    def velocities(self, rod=0) -> np.ndarray:
        m, d = self.model, self.data
        out = np.zeros((len(self.body_ids) + 1, 3))
        res = np.zeros(6)
        for k, b in enumerate(self.body_ids):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, int(b), res, 0)
            out[k] = res[3:]
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, int(self.tip_site), res, 0)
        out[-1] = res[3:]
        return out

    def set_velocities(self, rod, v: np.ndarray) -> None:
        """A free cable moving as a whole: every row of v (n + 1, 3) [m/s] equal, given to
        the root's free joint (a cable's vertices cannot move independently)."""
        v = np.asarray(v, dtype=float)
        if not np.allclose(v, v[0]):
            raise ValueError("a cable's vertex velocities can only be set as one translation (all rows equal)")
        m = self.model
        if m.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE:
            raise ValueError("only a free cable (not clamped) can be given a velocity")
        self.data.qvel[:3] = v[0]

    def set_positions(self, rod, x: np.ndarray) -> None:
        """Bend a clamped cable into the shape of ``x`` (its n + 1 vertices [m]), at rest.

        A cable's shape lives in its ball joints: the segments take the directions of
        x's edges, their frames carried along by parallel transport from the clamped
        first segment (no twist added). x's first edge must keep the clamp's direction.
        """
        self._set_segments(x, np.zeros(len(self.body_ids)))

    def _set_segments(self, x: np.ndarray, theta: np.ndarray) -> None:
        """Set the ball joints so that segment k runs along edge k of ``x`` (n + 1, 3) [m],
        its frame the Bishop frame turned by ``theta[k]`` [rad] about the segment."""
        x = np.asarray(x, dtype=float)
        if x.shape != (len(self.body_ids) + 1, 3):
            raise ValueError(f"x must have shape ({len(self.body_ids) + 1}, 3) (one row per vertex), "
                             f"got {x.shape}")
        m, d = self.model, self.data
        first = np.empty(9)
        mujoco.mju_quat2Mat(first, d.xquat[self.body_ids[0]])
        first = first.reshape(3, 3)  # columns: the segment's x (along it), y, z axes
        t = frames.tangents(x, closed=False)
        if not np.allclose(t[0], first[:, 0], atol=1e-6):
            raise ValueError("x's first edge must keep the direction of the clamped first segment")
        u = frames.bishop_frames(x, closed=False, u0=first[:, 1])
        m1, m2 = frames.material_frames(u, t, np.asarray(theta, dtype=float))
        quats = np.empty((len(t), 4))
        for k in range(len(t)):
            mujoco.mju_mat2Quat(quats[k], np.stack([t[k], m1[k], m2[k]], axis=1).ravel())
        inv_prev, rel, body_inv = np.empty(4), np.empty(4), np.empty(4)
        for k, b in enumerate(self.body_ids[1:], start=1):
            # joint = body_quat^-1 (q_{k-1}^-1 q_k): the turn from segment k - 1 to k.
            mujoco.mju_negQuat(inv_prev, quats[k - 1])
            mujoco.mju_mulQuat(rel, inv_prev, quats[k])
            mujoco.mju_negQuat(body_inv, m.body_quat[b])
            adr = m.jnt_qposadr[m.body_jntadr[b]]
            mujoco.mju_mulQuat(d.qpos[adr:adr + 4], body_inv, rel)
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)


def _require_cable() -> None:
    if not has_cable():
        raise ValueError(f"the cable plugin was removed in MuJoCo 4.0 (this is {mujoco.__version__}); "
                         "run in the MuJoCo 3.17 environment: make venv317")


def _cable_damping(mat, h: float, joint_damping_time: float) -> float:
    """Stiffness-proportional joint damping beta_d E I / h [N m s] for segments of length h [m]."""
    return joint_damping_time * mat.young * mat.second_moments[0] / h


def cable_rod(p, clamped: bool = True, gravity=None, start=(0.0, 0.0, 1.0), direction=(1.0, 0.0, 0.0),
              joint_damping_time: float = 0.01, scene: str | None = None) -> CableRod:
    """A cable for the benchmark parameters ``p``; joint damping = beta_d E I / h with
    beta_d = ``joint_damping_time`` [s] (stiffness-proportional, implicit: the cable
    needs it to be stable at large steps)."""
    _require_cable()
    mat = p.material
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    damping = _cable_damping(mat, p.length / p.n_edges, joint_damping_time)
    x = shapes.straight(p.length, p.n_edges, start, direction)
    spec = cable_spec(x, mat.radius, mat.density, mat.young, mat.shear_modulus, clamped, p.dt, grav, damping,
                      scene)
    return CableRod(spec.compile())


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


class CableRing(CableRod):
    """A naturally straight (``flat``) cable ring with total twist (see the comment above).

    n + 1 segments laid around the circle; the first is clamped, the last lies on it, welded
    to a world frame turned by Theta about the tangent. ``positions`` and ``set_positions``
    see the n ring vertices (the first n segments' origins) only.
    """

    def __init__(self, model: mujoco.MjModel, rest: np.ndarray, total_twist: float):
        super().__init__(model)
        self.rest = np.asarray(rest, dtype=float)
        self.total_twist = float(total_twist)
        self.set_positions(0, self.rest)

    def positions(self, rod=0) -> np.ndarray:
        return self.data.xpos[self.body_ids[:len(self.rest)]].copy()

    def velocities(self, rod=0) -> np.ndarray:
        return super().velocities()[:len(self.rest)]

    def set_positions(self, rod, x: np.ndarray) -> None:
        """Place the ring at ``x`` (n, 3) [m] at rest, twisted evenly; x's first two rows
        (the clamped segment) are ignored."""
        n = len(self.rest)
        self._set_segments(_ring_layout(self.rest, x), self.total_twist * np.arange(n + 1) / n)


def cable_ring(p, total_twist: float, joint_damping_time: float = 0.01) -> CableRing:
    """A naturally straight cable ring of circumference ``p.length`` with total twist
    ``total_twist`` [rad], without gravity (joint damping as :func:`cable_rod`)."""
    _require_cable()
    mat = p.material
    rest = ring_vertices(p)
    damping = _cable_damping(mat, float(np.linalg.norm(rest[1] - rest[0])), joint_damping_time)
    spec = cable_spec(np.concatenate([rest, rest[:2]]), mat.radius, mat.density, mat.young, mat.shear_modulus,
                      clamped=True, dt=p.dt, gravity=(0.0, 0.0, 0.0), joint_damping=damping)
    for geom in spec.geoms:  # the last segment overlaps the first: no contacts in the ring
        geom.contype = geom.conaffinity = 0
    first = spec.body("cB_first")  # a child of the world: its quat is its orientation
    target = np.empty(4)
    turn = np.empty(4)
    mujoco.mju_axisAngle2Quat(turn, np.array([1.0, 0.0, 0.0]), total_twist)  # about the segment
    mujoco.mju_mulQuat(target, np.asarray(first.quat, dtype=float), turn)
    spec.body("cB_last").add_site(name="ring_end")
    spec.worldbody.add_site(name="ring_start", pos=first.pos, quat=target)
    eq = spec.add_equality(name="ring_close", type=mujoco.mjtEq.mjEQ_WELD, name1="ring_end", name2="ring_start",
                           objtype=mujoco.mjtObj.mjOBJ_SITE)
    _stiff(eq, p.dt)
    return CableRing(spec.compile(), rest, total_twist)
