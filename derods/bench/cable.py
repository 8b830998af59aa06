"""MuJoCo 3.x's cable as a benchmark backend, built from the same rod description as derods.

The cable plugin (``mujoco.elasticity.cable`` on a ``<composite type="cable">``); MuJoCo
4.0 removed it, so it runs only in an environment with mujoco 3.17 (see the README for
the one command that makes it). The cable (:func:`cable_spec`): the same vertices as an
explicit ``vertex`` list, ``bend=E``, ``twist=G``, ``flat="true"`` (naturally straight),
geom mass rho A h per segment, no self-collision, ``initial="none"`` for a clamp, joint
damping 0.01 E I / h, ``implicitfast``. Its twisted ring for Michell's case is laid out as
the flexcomp's (see the comment above :class:`derods.bench.native.FlexRing`). Models are
composed with ``mujoco.MjSpec`` as in :mod:`derods.bench.native`; each rod class
implements the harness's protocol (:class:`derods.bench.backends.RodSimulator`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from .. import frames, shapes
from .native import CheckedSteps, NativeRod, _compose, _macro_spec, _numbers, _ring_layout, _stiff, ring_vertices


def has_cable() -> bool:
    """True if the installed MuJoCo still ships the cable plugin (3.x)."""
    return int(mujoco.__version__.split(".")[0]) < 4


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
        self._steps = CheckedSteps(m, self.data, self._dofs, self.label)
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


class CableRing(CableRod):
    """A naturally straight (``flat``) cable ring with total twist (laid out as the comment
    above :class:`derods.bench.native.FlexRing` says).

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
