"""MuJoCo's native rods, built from the same rod description as derods.

Backends:

* ``flex``: MuJoCo's 1D flexcomp with ``<elasticity young poisson>`` (MuJoCo's
  own discrete elastic rod; MuJoCo 3.17 bends only, 4.x also twists through
  per-edge twist joints), ``<edge equality>`` for inextensibility and
  ``<pin>`` for clamps, integrated with the ``discrete`` integrator.
* ``cable``: MuJoCo 3.x's cable plugin (``mujoco.elasticity.cable`` on a
  ``<composite type="cable">``); MuJoCo 4.0 removed it, so it runs only in an
  environment with mujoco 3.17 (see the README for the one command that makes it).

Parameter mapping (a careful user's settings; pitfalls measured in the native
rod baselines):

* length L, radius r, n edges: flexcomp ``type="direct"`` with points i L / n
  (``type="grid"`` refuses spacing <= radius), ``radius=r``.
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
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .world import MAX_SPEED, DivergenceError


def has_flex_elasticity() -> bool:
    """True if the installed MuJoCo has 1D flex elasticity (3.17 and later)."""
    major, minor = (int(v) for v in mujoco.__version__.split(".")[:2])
    return (major, minor) >= (3, 17)


def has_cable() -> bool:
    """True if the installed MuJoCo still ships the cable plugin (3.x)."""
    return int(mujoco.__version__.split(".")[0]) < 4


def poisson_for(young: float, shear: float) -> tuple[float, bool]:
    """flexcomp's Poisson ratio for E and G, clipped to [0, 0.4999]; (nu, clipped)."""
    nu = young / (2.0 * shear) - 1.0
    clipped = min(max(nu, 0.0), 0.4999)
    return clipped, clipped != nu


def flex_xml(points: np.ndarray, radius: float, mass: float, young: float, poisson: float,
             closed: bool = False, pinned=(), dt: float = 1e-2, gravity=(0.0, 0.0, -9.81),
             scene_body: str = "", contact_solref=(0.005, 1.0)) -> str:
    """MJCF of one flexcomp rod (plus optional scene geoms in ``scene_body``)."""
    n = len(points) if closed else len(points) - 1
    pts = " ".join(f"{v:.9g}" for v in np.asarray(points).ravel())
    elem = " ".join(f"{i} {(i + 1) % len(points)}" for i in range(n))
    pin = f'<pin id="{" ".join(str(i) for i in pinned)}"/>' if len(pinned) else ""
    g = " ".join(f"{v:g}" for v in gravity)
    return f"""<mujoco>
  <option timestep="{dt}" integrator="discrete" gravity="{g}"/>
  <worldbody>
    {scene_body}
    <flexcomp name="rod" type="direct" dim="1" point="{pts}" element="{elem}" radius="{radius}"
              mass="{mass}" rgba="0.2 0.6 0.85 1">
      {pin}
      <edge equality="true" solref="0.0001 1"/>
      <contact selfcollide="none" condim="3" solref="{contact_solref[0]} {contact_solref[1]}"/>
      <elasticity young="{young}" poisson="{poisson}" damping="0"/>
    </flexcomp>
  </worldbody>
</mujoco>"""


class NativeRod:
    """One native flexcomp rod in its own MuJoCo model, with the World methods the
    benchmark cases use (step, positions, velocities, set_positions, time)."""

    def __init__(self, xml: str, mass_damping: float = 0.0):
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        adr, num = m.flex_vertadr[0], m.flex_vertnum[0]
        self.body_ids = m.flex_vertbodyid[adr:adr + num]
        self.free = np.array([m.body_dofnum[b] > 0 for b in self.body_ids])
        self.dofs = np.concatenate([m.body_dofadr[b] + np.arange(3) for b in self.body_ids[self.free]])
        if mass_damping:
            for b in self.body_ids[self.free]:
                m.dof_damping[m.body_dofadr[b]:m.body_dofadr[b] + 3] = mass_damping * m.body_mass[b]
        self.n_steps = 0
        self._badqacc = 0
        mujoco.mj_forward(m, self.data)

    active_terms = {"rod": ("native",)}

    @property
    def time(self) -> float:
        return float(self.data.time)

    def positions(self, name=None) -> np.ndarray:
        # flexvert_xpos covers pinned vertices too (their "body" is the world).
        adr, num = self.model.flex_vertadr[0], self.model.flex_vertnum[0]
        return self.data.flexvert_xpos[adr:adr + num].copy()

    def velocities(self, name=None) -> np.ndarray:
        v = np.zeros((len(self.body_ids), 3))
        v[self.free] = self.data.qvel[self.dofs].reshape(-1, 3)
        return v

    def set_positions(self, name, x: np.ndarray) -> None:
        m, d = self.model, self.data
        for i, b in enumerate(self.body_ids):
            if self.free[i]:
                jnt = m.body_jntadr[b]
                d.qpos[m.jnt_qposadr[jnt]:m.jnt_qposadr[jnt] + 3] = x[i] - m.body_pos[b]
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)

    def step(self, n_steps: int = 1) -> None:
        for _ in range(n_steps):
            mujoco.mj_step(self.model, self.data)
            self.n_steps += 1
            self._check()

    def _check(self) -> None:
        d = self.data
        bad = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        v = d.qvel[self.dofs]
        speed = np.max(np.abs(v)) if len(v) else 0.0
        if bad != self._badqacc or not speed <= MAX_SPEED:
            self._badqacc = bad
            what = "MuJoCo reported bad accelerations (BADQACC)" if bad else f"vertex speed {speed:.3g} m/s"
            raise DivergenceError(f"native rod diverged at step {self.n_steps} (t = {d.time:.6g} s): {what}")


def body_of_vertex(rod: NativeRod, i: int) -> int:
    """MuJoCo body id of vertex i (for xfrc_applied)."""
    return int(rod.body_ids[i])


def flex_rod(points: np.ndarray, p, pinned=(), gravity=None, closed: bool = False, scene_body: str = "",
             mass_damping: float = 0.0) -> tuple[NativeRod, dict]:
    """A native flexcomp rod for the benchmark parameters ``p`` (:class:`derods.bench.CaseParams`).

    Returns the rod and the mapping notes (e.g. a clipped Poisson ratio).
    """
    mat = p.material
    nu, clipped = poisson_for(mat.young, mat.shear_modulus)
    length = p.length
    mass = mat.density * math.pi * mat.radius**2 * length
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    xml = flex_xml(points, mat.radius, mass, mat.young, nu, closed, pinned, p.dt, grav, scene_body)
    notes = {"poisson": nu, "poisson_clipped": clipped}
    return NativeRod(xml, mass_damping), notes


def cable_xml(length: float, n_edges: int, radius: float, density: float, young: float, shear: float,
              start=(0.0, 0.0, 1.0), direction=(1.0, 0.0, 0.0), clamped: bool = True, dt: float = 1e-2,
              gravity=(0.0, 0.0, -9.81), joint_damping: float = 0.0, scene_body: str = "") -> str:
    """MJCF of a MuJoCo 3.x cable (``<composite type="cable">`` with the elasticity plugin).

    ``geom mass = rho A h`` per segment (the default density would add the capsules'
    end caps: 3.7x too heavy at n = 200); ``initial="none"`` welds the first segment
    (the clamp), ``"free"`` gives it a free joint; joint damping [N m s] on the ball
    joints, implicit in MuJoCo's integrators.
    """
    h = length / n_edges
    seg_mass = density * math.pi * radius**2 * h
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    # curve "s" lays the cable along +x; "s s s" scaled per axis lays it along ``direction``.
    along_x = np.allclose(d, (1.0, 0.0, 0.0))
    curve = "s" if along_x else "s s s"
    size = f"{length}" if along_x else " ".join(f"{length * c:.9g}" for c in d)
    g = " ".join(f"{v:g}" for v in gravity)
    return f"""<mujoco>
  <extension><plugin plugin="mujoco.elasticity.cable"/></extension>
  <compiler angle="radian"/>
  <option timestep="{dt}" integrator="implicitfast" gravity="{g}"/>
  <worldbody>
    {scene_body}
      <composite prefix="c" type="cable" curve="{curve}" count="{n_edges + 1} 1 1" size="{size}"
                 offset="{start[0]} {start[1]} {start[2]}" initial="{'none' if clamped else 'free'}">
        <plugin plugin="mujoco.elasticity.cable">
          <config key="twist" value="{shear}"/>
          <config key="bend" value="{young}"/>
          <config key="vmax" value="0"/>
        </plugin>
        <joint kind="main" damping="{joint_damping}"/>
        <geom type="capsule" size="{radius}" mass="{seg_mass}" rgba="0.85 0.55 0.2 1" condim="3"/>
      </composite>
  </worldbody>
</mujoco>"""


class CableRod(NativeRod):
    """A MuJoCo 3.x cable with the World methods the benchmark cases use.

    Vertices are the segment bodies' origins plus the tip site; velocities are the
    linear velocities of those points.
    """

    def __init__(self, xml: str):
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        names = [m.body(i).name for i in range(m.nbody)]
        self.body_ids = np.array([i for i, nm in enumerate(names) if nm.startswith("cB_")])
        self.tip_site = m.site("cS_last").id
        self.dofs = np.arange(m.nv)
        self.free = np.ones(len(self.body_ids) + 1, dtype=bool)
        self.n_steps = 0
        self._badqacc = 0
        mujoco.mj_forward(m, self.data)

    def positions(self, name=None) -> np.ndarray:
        return np.concatenate([self.data.xpos[self.body_ids], self.data.site_xpos[[self.tip_site]]])

    def velocities(self, name=None) -> np.ndarray:
        m, d = self.model, self.data
        out = np.zeros((len(self.body_ids) + 1, 3))
        res = np.zeros(6)
        for k, b in enumerate(self.body_ids):
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, int(b), res, 0)
            out[k] = res[3:]
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, int(self.tip_site), res, 0)
        out[-1] = res[3:]
        return out

    def set_positions(self, name, x: np.ndarray) -> None:
        """Bend a clamped cable into the shape of ``x`` (its n + 1 vertices [m]), at rest.

        A cable's shape lives in its ball joints: each segment is turned, relative to
        the one before, by the angle between their directions in ``x``. Only shapes in
        the xz plane (the benchmark's) are supported.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (len(self.body_ids) + 1, 3) or np.max(np.abs(x[:, 1] - x[0, 1])) > 1e-12:
            raise ValueError("set_positions on a cable takes n + 1 vertices in the xz plane")
        e = np.diff(x, axis=0)
        pitch = np.arctan2(e[:, 2], e[:, 0])  # angle of each segment above +x
        m, d = self.model, self.data
        for k, b in enumerate(self.body_ids[1:], start=1):
            turn = pitch[k] - pitch[k - 1]  # about -y: +x turns towards +z
            adr = m.jnt_qposadr[m.body_jntadr[b]]
            d.qpos[adr:adr + 4] = [math.cos(turn / 2), 0.0, -math.sin(turn / 2), 0.0]
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)


def cable_rod(p, clamped: bool = True, gravity=None, start=(0.0, 0.0, 1.0), direction=(1.0, 0.0, 0.0),
              joint_damping_time: float = 0.01, scene_body: str = "") -> CableRod:
    """A cable for the benchmark parameters ``p``; joint damping = beta_d E I / h with
    beta_d = ``joint_damping_time`` [s] (stiffness-proportional, implicit: the cable
    needs it to be stable at large steps)."""
    if not has_cable():
        raise ValueError(f"the cable plugin was removed in MuJoCo 4.0 (this is {mujoco.__version__}); "
                         "run in the MuJoCo 3.17 environment: make venv317")
    mat = p.material
    grav = (0.0, 0.0, -p.gravity) if gravity is None else gravity
    h = p.length / p.n_edges
    damping = joint_damping_time * mat.young * mat.second_moments[0] / h
    xml = cable_xml(p.length, p.n_edges, mat.radius, mat.density, mat.young, mat.shear_modulus, start,
                    direction, clamped, p.dt, grav, damping, scene_body)
    return CableRod(xml)
