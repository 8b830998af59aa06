"""Rods in MuJoCo: one body per vertex, driven by DER forces every step.

Each rod becomes a chain of MuJoCo bodies, one per vertex, each with three
world-aligned slide joints (none for a vertex held by a pin or a clamp), and
a 1D flex over those bodies with no MuJoCo elasticity: the flex only makes the
edges collide as capsules of the rod radius (thin obstacles cannot slip
between vertices). Everything elastic comes from derods.

Every step, for all rods at once:

1. read vertex positions ``xpos`` and velocities ``qvel``;
2. transport the reference frames, solve the quasistatic twist and evaluate
   the DER forces and their PSD Hessian (:meth:`derods.Rod.step_terms`);
3. implicit mode: solve the linearly implicit backward Euler step
   (:mod:`derods.implicit`) with gravity, the user's ``xfrc_applied`` and the
   previous step's constraint (contact) force, and apply the force that makes
   MuJoCo's velocity update reproduce it, f = M dv / h - (gravity + contact +
   user); explicit mode: apply the DER force itself;
4. ``mj_step``: MuJoCo integrates, and handles contact, friction and the
   rest of the scene.

derods writes its forces into ``qfrc_applied`` of the rod dofs and leaves
``xfrc_applied`` to the user and the interactive viewer (whose mouse pulls
enter the implicit step as external forces).

Damping has a physical meaning: ``mass_damping`` a [1/s] is a drag -a m v on
every vertex (as in a viscous medium; every mode decays at rate a/2);
``stiffness_damping`` b [s] is internal (Kelvin-Voigt-like) viscosity -b K v,
which damps a mode of angular frequency w at rate b w^2 / 2. Backward Euler
adds numerical damping of its own at large steps.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np

from .. import frames
from . import contact
from .divergence import MAX_SPEED, MAX_STRAIN, DivergenceError  # noqa: F401
from .implicit import ImplicitSystem, restrict_band
from ..stencil import ring_order
from ..geometry import edges as _edges
from ..rod import Rod, RodState
from ..twist import TwistBoundary

END_KINDS = ("free", "pin", "clamp")
MODES = ("auto", "implicit", "explicit", "projection")

@dataclass(frozen=True)
class ContactParams:
    """How rods touch the scene.

    friction: sliding friction coefficient. solref: MuJoCo (timeconst [s],
    dampratio); a time constant near 2 dt keeps fast impacts from sinking in.
    solimp: MuJoCo's impedance (dmin, dmax, width [m], midpoint, power); an
    impedance closer to 1 makes contacts harder and lets less friction creep.
    condim: contact dimensionality (1 frictionless, 3 sliding friction, 4 or 6
    adds torsional / rolling). self_collision: edges of a rod collide with its
    other edges (neighbours excluded); off by default.
    """

    friction: float = 1.0
    solref: tuple[float, float] = (0.005, 1.0)
    solimp: tuple[float, ...] = (0.9, 0.95, 0.001, 0.5, 2.0)
    condim: int = 3
    self_collision: bool = False


@dataclass
class _Slot:
    """Bookkeeping of one rod inside the world."""

    name: str
    rod: Rod
    x0: np.ndarray
    start: str
    end: str
    rgba: tuple
    fixed: np.ndarray  # (n_vertices,) bool
    body_ids: np.ndarray = field(default=None)
    dof_ids: np.ndarray = field(default=None)  # dofs of the free vertices in solve order, (3 n_free,)
    qpos_ids: np.ndarray = field(default=None)  # their qpos entries in vertex order, (3 n_free,)
    free: slice = field(default=None)  # free vertex range
    order: np.ndarray = field(default=None)  # free vertices in solve order (zig-zag on a ring)
    state: RodState = field(default=None)
    mass: np.ndarray = field(default=None)  # per free dof [kg]
    bodies: dict = field(default_factory=dict)  # end -> name of the MuJoCo body holding it
    held: dict = field(default_factory=dict)  # end -> vertex indices held by that end
    director: dict = field(default_factory=dict)  # end -> clamp's material director in body frame
    theta_end: dict = field(default_factory=dict)  # end -> unwrapped twist angle of the clamped edge
    reaction: np.ndarray = field(default=None)  # what derods last added to qfrc_applied


def _held_vertices(n_vertices: int, start: str, end: str) -> np.ndarray:
    fixed = np.zeros(n_vertices, dtype=bool)
    held = {"free": 0, "pin": 1, "clamp": 2}
    fixed[: held[start]] = True
    if held[end]:
        fixed[-held[end]:] = True
    return fixed


def _twist_boundary(rod: Rod, start: str, end: str, name: str) -> TwistBoundary:
    bd = rod.boundary
    if start == "clamp" and end == "clamp":
        return bd if bd.kind == "clamped" else TwistBoundary("clamped", 0.0, 0.0)
    if bd.kind == "clamped":
        raise ValueError(
            f"rod '{name}': TwistBoundary('clamped') needs start='clamp' and end='clamp', "
            f"got start={start!r}, end={end!r}"
        )
    if start == "clamp":
        return TwistBoundary("free", theta_first=bd.theta_first or 0.0)
    if end == "clamp":
        return TwistBoundary("free", theta_last=bd.theta_last or 0.0)
    return TwistBoundary("free")


class World:
    """A MuJoCo scene with DER rods in it.

    scene: None for an empty world, a path to an MJCF file, or a ``mujoco.MjSpec``.
    dt: time step [s]; None keeps the scene's (MuJoCo's default 2e-3).
    gravity: [m/s^2], shape (3,); None keeps the scene's.
    mode: "implicit", "explicit", "auto" (implicit when dt exceeds half the
        estimated explicit stability limit of the stiffest rod), or "projection":
        the DER paper's method, an implicit step for bending and twisting with
        inextensibility enforced by fast projection (:mod:`derods.projection`)
        instead of a stiff stretching term; MuJoCo then resolves contacts with
        the bare vertex masses, as in the explicit mode.
    mass_damping: a [1/s]; stiffness_damping: b [s] (see the module docstring).
    contact: :class:`ContactParams` for all rods.
    integrator: MuJoCo integrator name for a new world ("implicitfast" by default);
        a scene keeps its own unless given.

    Add rods with :meth:`add_rod`, then :meth:`step`. The MuJoCo model is
    compiled on first use and available as :attr:`model` and :attr:`data`.
    """

    def __init__(self, scene=None, *, dt: float | None = None, gravity=None, mode: str = "auto",
                 mass_damping: float = 0.0, stiffness_damping: float = 0.0,
                 contact: ContactParams = ContactParams(), integrator: str | None = None):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if dt is not None and not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0 [s], got {dt!r}")
        if mass_damping < 0 or stiffness_damping < 0:
            raise ValueError(
                f"damping must be >= 0: mass_damping={mass_damping!r} [1/s], "
                f"stiffness_damping={stiffness_damping!r} [s]"
            )
        if isinstance(scene, mujoco.MjSpec):
            self.spec = scene
        elif scene is None:
            self.spec = mujoco.MjSpec()
            self.spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        else:
            try:
                self.spec = mujoco.MjSpec.from_file(str(scene))
            except Exception as err:  # MuJoCo raises ValueError with its parser message
                raise ValueError(f"cannot read MJCF scene {str(scene)!r}: {err}") from None
        if integrator is not None:
            self.spec.option.integrator = getattr(mujoco.mjtIntegrator, "mjINT_" + integrator.upper())
        if dt is not None:
            self.spec.option.timestep = dt
        if gravity is not None:
            self.spec.option.gravity = np.asarray(gravity, dtype=float)
        self.requested_mode = mode
        self.mass_damping = float(mass_damping)
        self.stiffness_damping = float(stiffness_damping)
        self.contact = contact
        self._slots: list[_Slot] = []
        self._model = None
        self._data = None
        self.mode = None
        self.explicit_dt_limit = None
        self.n_steps = 0

    # -- building ------------------------------------------------------------
    def add_rod(self, rod: Rod, name: str | None = None, *, start: str = "free", end: str = "free",
                x: np.ndarray | None = None, rgba=(0.85, 0.25, 0.15, 1.0), start_body: str | None = None,
                end_body: str | None = None) -> int:
        """Add a rod; returns its index.

        rod: the :class:`derods.Rod`, open or closed (a ring: ends stay "free").
        start, end: "free", "pin" (the end vertex held in place) or "clamp" (the end
            edge held in place and its material frame fixed; the continuum clamp
            then sits at the middle of that edge, see :func:`derods.shapes.cantilever`).
        x: initial vertex positions [m], shape (n_vertices, 3); default ``rod.rest_x``.
        start_body, end_body: name of a MuJoCo body of the scene that holds that end
            (default: the world). The end then moves with the body, a clamp turns its
            material frame with the body, and the body feels the rod's force and
            (through a clamp) its bending and twisting moments.
        """
        if self._model is not None:
            raise RuntimeError("add rods before the world is compiled (before the first step)")
        if rod.closed and (start != "free" or end != "free"):
            raise ValueError("a ring has no ends: leave start and end 'free'")
        if rod.rest_x.ndim != 2:
            raise ValueError("add rods to a World one at a time (rest_x of shape (n_vertices, 3))")
        for key, val in (("start", start), ("end", end)):
            if val not in END_KINDS:
                raise ValueError(f"{key} must be one of {END_KINDS}, got {val!r}")
        name = name or f"rod{len(self._slots)}"
        if any(s.name == name for s in self._slots):
            raise ValueError(f"a rod named {name!r} exists already; pass another name")
        x0 = rod.rest_x if x is None else np.asarray(x, dtype=float)
        if x0.shape != rod.rest_x.shape:
            raise ValueError(f"x must have shape {rod.rest_x.shape}, got {x0.shape}")
        fixed = _held_vertices(rod.n_vertices, start, end)
        if fixed.all():
            raise ValueError(f"rod '{name}' has every vertex held; give it more edges")
        bodies = {}
        for key, body, kind in (("start", start_body, start), ("end", end_body, end)):
            if body is None:
                continue
            if kind == "free":
                raise ValueError(f"{key}_body={body!r} needs {key}='pin' or 'clamp'")
            if self.spec.body(body) is None:
                names = [b.name for b in self.spec.bodies if b.name]
                raise ValueError(f"{key}_body {body!r} is not a body of the scene; bodies: {names}")
            bodies[key] = body
        if not rod.closed:
            rod = rod.with_boundary(_twist_boundary(rod, start, end, name))
        if self.requested_mode == "projection":
            if rod.closed:
                raise ValueError("mode='projection' handles open rods only; use mode='implicit' for rings")
            # Edge lengths are held by projection; a vanishing spring keeps the term's bookkeeping.
            rod = replace(rod, stretch_stiffness=1e-9 * rod.material.stretch_stiffness)
        slot = _Slot(name, rod, x0, start, end, tuple(rgba), fixed)
        slot.bodies = bodies
        n_held = {"free": 0, "pin": 1, "clamp": 2}
        nv = rod.n_vertices
        slot.held = {"start": np.arange(n_held[start]), "end": np.arange(nv - n_held[end], nv)}
        self._slots.append(slot)
        return len(self._slots) - 1

    def _scene_has_obstacles(self) -> bool:
        return any(g.contype or g.conaffinity for g in self.spec.geoms)

    def compile(self) -> None:
        """Build the MuJoCo model (done automatically on first use)."""
        if self._model is not None:
            return
        if not self._slots:
            raise ValueError("the world has no rods; add one with add_rod()")
        collide = self._scene_has_obstacles()
        poses = {}
        if any(slot.bodies for slot in self._slots):
            # World poses of the bodies that hold rod ends, at the scene's initial state.
            base = self.spec.compile()
            bdata = mujoco.MjData(base)
            mujoco.mj_kinematics(base, bdata)
            for slot in self._slots:
                for body in slot.bodies.values():
                    b = base.body(body).id
                    poses[body] = (bdata.xpos[b].copy(), bdata.xmat[b].reshape(3, 3).copy())
        for slot in self._slots:
            self._add_to_spec(slot, collide, poses)
        with warnings.catch_warnings():
            # Our flexes carry no MuJoCo elasticity by design: derods supplies it.
            warnings.filterwarnings("ignore", message=".*has no equality constraints or passive forces")
            self._model = self.spec.compile()
        self._data = mujoco.MjData(self._model)
        mujoco.mj_forward(self._model, self._data)  # positions of every body
        m = self._model
        for slot in self._slots:
            slot.body_ids = np.array([m.body(f"{slot.name}_{i}").id for i in range(slot.rod.n_vertices)])
            free = np.flatnonzero(~slot.fixed)
            slot.free = slice(int(free[0]), int(free[-1]) + 1)
            closed = slot.rod.closed
            slot.order = ring_order(slot.rod.n_vertices) if closed else np.arange(slot.free.start, slot.free.stop)
            slot.dof_ids = (m.body_dofadr[slot.body_ids[slot.order]][:, None] + np.arange(3)).ravel()
            jnt = m.body_jntadr[slot.body_ids[slot.free]][:, None] + np.arange(3)
            slot.qpos_ids = m.jnt_qposadr[jnt].ravel()
            slot.mass = np.repeat(m.body_mass[slot.body_ids[slot.order]], 3)
            x = slot.x0
            t = frames.tangents(x, closed)
            state = RodState(x.copy(), frames.bishop_frames(x, closed, slot.rod.u0), t, np.zeros(len(t)))
            slot.state = slot.rod.advance(state, x)
            slot.reaction = np.zeros(m.nv)
            m1 = slot.state.u  # theta = 0 at the start: the material frame is the reference frame
            for key, body in slot.bodies.items():
                kind = slot.start if key == "start" else slot.end
                if kind == "clamp":
                    edge = 0 if key == "start" else slot.rod.n_edges - 1
                    rmat = self._data.xmat[m.body(body).id].reshape(3, 3)
                    slot.director[key] = rmat.T @ m1[edge]
                    slot.theta_end[key] = float(slot.state.theta[edge])
        self._moving_clamps = any(slot.bodies for slot in self._slots)
        self._dofs = np.concatenate([s.dof_ids for s in self._slots])
        self._mass = np.concatenate([s.mass for s in self._slots])
        self._offsets = np.concatenate([[0], np.cumsum([len(s.dof_ids) for s in self._slots])]).astype(int)
        self._free_bodies = np.concatenate([s.body_ids[s.order] for s in self._slots])
        self._local_of_dof = np.full(m.nv, -1)
        self._local_of_dof[self._dofs] = np.arange(len(self._dofs))
        self._contact = np.zeros(len(self._dofs))
        self.explicit_dt_limit = self._estimate_explicit_dt()
        h = m.opt.timestep
        if self.requested_mode == "auto":
            self.mode = "implicit" if h > 0.5 * self.explicit_dt_limit else "explicit"
        else:
            self.mode = self.requested_mode
        supported = (mujoco.mjtIntegrator.mjINT_EULER, mujoco.mjtIntegrator.mjINT_IMPLICIT,
                     mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
        if self.mode == "implicit" and m.opt.integrator not in supported:
            name = mujoco.mjtIntegrator(m.opt.integrator).name
            raise ValueError(
                f"the implicit rod step needs MuJoCo's Euler, implicit or implicitfast integrator, "
                f"the scene uses {name}; pass integrator='implicitfast' to World"
            )
        self._badqacc = self._data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number

    def _add_to_spec(self, slot: _Slot, collide: bool, poses: dict) -> None:
        rod = slot.rod
        mass = rod.vertex_mass
        r = rod.material.radius
        holder = {}
        for key, body in slot.bodies.items():
            for i in slot.held[key]:
                holder[int(i)] = body
        names = []
        for i, xi in enumerate(slot.x0):
            if i in holder:
                # A vertex held by a body rides on it, placed in the body's frame.
                p, rmat = poses[holder[i]]
                body = self.spec.body(holder[i]).add_body(name=f"{slot.name}_{i}", pos=rmat.T @ (xi - p))
            else:
                body = self.spec.worldbody.add_body(name=f"{slot.name}_{i}", pos=xi)
            body.mass = float(mass[i])
            body.inertia = [0.5 * float(mass[i]) * r * r] * 3
            body.explicitinertial = True
            if not slot.fixed[i]:
                for k, axis in enumerate(np.eye(3)):
                    body.add_joint(name=f"{slot.name}_{i}_{'xyz'[k]}", type=mujoco.mjtJoint.mjJNT_SLIDE,
                                   axis=axis)
            names.append(body.name)
        flex = self.spec.add_flex()
        flex.name = slot.name
        flex.dim = 1
        flex.radius = r
        flex.vertbody = names
        j = np.arange(rod.n_edges)
        flex.elem = np.column_stack([j, (j + 1) % rod.n_vertices]).ravel().tolist()
        flex.rgba = list(slot.rgba)
        c = self.contact
        # Collision work only where there is something to collide with.
        flex.contype = flex.conaffinity = 1 if (collide or c.self_collision) else 0
        flex.condim = c.condim
        flex.friction = [c.friction, 0.005, 0.0001]
        flex.solref = list(c.solref)
        flex.solimp = list(c.solimp)
        flex.selfcollide = (mujoco.mjtFlexSelf.mjFLEXSELF_AUTO if c.self_collision
                            else mujoco.mjtFlexSelf.mjFLEXSELF_NONE)

    def _estimate_explicit_dt(self) -> float:
        """2 / omega_max of the stiffest rod, omega_max^2 bounded by Gershgorin on M^-1 K."""
        limit = math.inf
        for slot in self._slots:
            band, rank1, _ = self._solve_terms(slot, slot.rod.step_terms(slot.state, slot.state.x))
            ab = np.abs(band)
            rows = ab.sum(axis=0)
            for d in range(1, ab.shape[0]):
                rows[d:] += ab[d, :-d]
            if rank1 is not None:
                g = np.abs(rank1[0])
                rows += rank1[1] * g * g.sum()
            w2 = np.max(rows / slot.mass)
            if w2 > 0:
                limit = min(limit, 2.0 / math.sqrt(w2))
        return limit

    # -- access --------------------------------------------------------------
    @property
    def model(self) -> mujoco.MjModel:
        self.compile()
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        self.compile()
        return self._data

    @property
    def rods(self) -> list[Rod]:
        return [s.rod for s in self._slots]

    @property
    def rod_names(self) -> list[str]:
        return [s.name for s in self._slots]

    def _slot(self, rod) -> _Slot:
        if isinstance(rod, str):
            for s in self._slots:
                if s.name == rod:
                    return s
            raise KeyError(f"no rod named {rod!r}; rods: {self.rod_names}")
        return self._slots[rod]

    def positions(self, rod: int | str = 0) -> np.ndarray:
        """Vertex positions [m] of a rod, shape (n_vertices, 3)."""
        return self._positions(self._slot(rod))

    def _positions(self, slot: _Slot) -> np.ndarray:
        # From qpos, not xpos: after mj_step, xpos still holds the kinematics of the
        # state *before* the integration, one step behind.
        x = slot.x0.copy()
        x[slot.free] += self.data.qpos[slot.qpos_ids].reshape(-1, 3)
        for key in slot.bodies:
            # Held by a moving body (xpos is current: _step_once runs mj_kinematics first).
            x[slot.held[key]] = self.data.xpos[slot.body_ids[slot.held[key]]]
        return x

    def set_positions(self, rod: int | str, x: np.ndarray) -> None:
        """Move a rod's free vertices to ``x`` [m], shape (n_vertices, 3), at rest.

        Held vertices (pins, clamps) stay where they are; frames are carried along.
        """
        s = self._slot(rod)
        x = np.asarray(x, dtype=float)
        if x.shape != s.x0.shape:
            raise ValueError(f"x must have shape {s.x0.shape}, got {x.shape}")
        d = self.data
        d.qpos[s.qpos_ids] = (x - s.x0)[s.free].ravel()
        d.qvel[s.dof_ids] = 0.0
        mujoco.mj_forward(self._model, d)
        s.state = s.rod.advance(s.state, self._positions(s))

    def velocities(self, rod: int | str = 0) -> np.ndarray:
        """Vertex velocities [m/s] of a rod, shape (n_vertices, 3) (zero where held)."""
        s = self._slot(rod)
        v = np.zeros((s.rod.n_vertices, 3))
        v[s.order] = self.data.qvel[s.dof_ids].reshape(-1, 3)
        return v

    def contact_force(self, rod: int | str = 0) -> np.ndarray:
        """Contact (constraint) force [N] on each vertex in the last step, shape (n_vertices, 3).

        In implicit mode this is the force derods solved for in the implicit
        metric (plus MuJoCo's for rows it left to MuJoCo); in explicit mode, MuJoCo's.
        """
        s = self._slot(rod)
        out = np.zeros((s.rod.n_vertices, 3))
        if self.mode == "implicit":
            i = self._slots.index(s)
            out[s.order] = self._contact[self._offsets[i]:self._offsets[i + 1]].reshape(-1, 3)
        else:
            out[s.order] = self.data.qfrc_constraint[s.dof_ids].reshape(-1, 3)
        return out

    def rod_state(self, rod: int | str = 0) -> RodState:
        """The rod's current :class:`RodState` (frames and twist of the last step)."""
        return self._slot(rod).state

    @property
    def active_terms(self) -> dict[str, tuple[str, ...]]:
        """The energy terms each rod evaluates, by rod name."""
        return {s.name: s.rod.active_terms for s in self._slots}

    @property
    def time(self) -> float:
        return float(self.data.time)

    # -- stepping ------------------------------------------------------------
    def step(self, n_steps: int = 1) -> None:
        """Advance ``n_steps`` steps of ``model.opt.timestep``."""
        self.compile()
        for _ in range(n_steps):
            self._step_once()

    def _step_once(self) -> None:
        m, d = self._model, self._data
        h = m.opt.timestep
        bands, rank1, grads = [], [], []
        if self._moving_clamps:
            mujoco.mj_kinematics(m, d)  # after mj_step, xpos still shows the previous state
        for slot in self._slots:
            x = self._positions(slot)
            self._check_strain(slot, x)
            boundary = self._clamp_boundary(slot, x) if slot.director else None
            terms = slot.rod.step_terms(slot.state, x, boundary=boundary)
            slot.state = terms.state
            if slot.bodies:
                self._apply_reaction(slot, x, terms)
            band, r1, grad = self._solve_terms(slot, terms)
            bands.append(band)
            rank1.append(r1)
            grads.append(grad)
        dofs, mass = self._dofs, self._mass
        v = d.qvel[dofs]
        system = ImplicitSystem(h, self._offsets, bands, rank1, mass, self.mass_damping,
                                self.stiffness_damping)
        grad = np.concatenate(grads)
        if self.mode == "explicit":
            force = -grad - self.mass_damping * mass * v
            if self.stiffness_damping:
                force -= self.stiffness_damping * system.k_matvec(v)
            d.qfrc_applied[dofs] = force
            mujoco.mj_step(m, d)
        elif self.mode == "projection":
            self._projection_step(system, grad, v)
        else:
            self._implicit_step(system, grad, v)
        self.n_steps += 1
        self._check_divergence(dofs)

    def _clamp_boundary(self, slot: _Slot, x: np.ndarray) -> TwistBoundary:
        """This step's twist boundary: clamped edges turn with the bodies holding them."""
        t = frames.tangents(x, False)
        u = frames.time_parallel_transport(slot.state.u, slot.state.t, t)
        for key, d_body in slot.director.items():
            edge = 0 if key == "start" else slot.rod.n_edges - 1
            rmat = self._data.xmat[self._model.body(slot.bodies[key]).id].reshape(3, 3)
            angle = float(frames.signed_angle(u[edge], rmat @ d_body, t[edge]))
            # Unwrap: a clamp turned many times carries many turns of twist.
            prev = slot.theta_end[key]
            slot.theta_end[key] = prev + (angle - prev + np.pi) % (2 * np.pi) - np.pi
        bd = slot.rod.boundary
        if bd.kind == "clamped":
            return TwistBoundary("clamped", slot.theta_end.get("start", bd.theta_first),
                                 slot.theta_end.get("end", bd.theta_last))
        return TwistBoundary("free", theta_first=slot.theta_end.get("start", bd.theta_first),
                             theta_last=slot.theta_end.get("end", bd.theta_last))

    def _apply_reaction(self, slot: _Slot, x: np.ndarray, terms) -> None:
        """The rod's force and twisting moment on the bodies holding its ends (explicit)."""
        m, d = self._model, self._data
        qfrc = np.zeros(m.nv)
        grad = terms.grad_x
        t = frames.tangents(x, False)
        for key, body in slot.bodies.items():
            b = m.body(body).id
            for i in slot.held[key]:
                mujoco.mj_applyFT(m, d, -grad[i], np.zeros(3), x[i], b, qfrc)
            if key in slot.director:
                # The rod resists the turn of its clamped edge: torque -dE/dtheta about t.
                edge = 0 if key == "start" else -1
                if terms.twist is not None:
                    dedtheta = float(terms.twist.lam) * (1.0 if key == "end" else -1.0)
                elif terms.grad_theta is not None:
                    dedtheta = float(terms.grad_theta[edge])
                else:
                    continue
                mujoco.mj_applyFT(m, d, np.zeros(3), -dedtheta * t[edge], x[slot.held[key][0]], b, qfrc)
        d.qfrc_applied[:] += qfrc - slot.reaction
        slot.reaction = qfrc

    @staticmethod
    def _solve_terms(slot: _Slot, terms) -> tuple[np.ndarray, tuple | None, np.ndarray]:
        """A rod's Hessian band, rank-one twist term and gradient over its free dofs,
        in solve order (the zig-zag order on a ring)."""
        tw = terms.twist
        if slot.rod.closed:
            band = terms.hessian_banded  # already in slot.order (stencil.ring_order)
            pick = lambda a: a.reshape(-1, 3)[slot.order].ravel()  # noqa: E731
        else:
            lo, hi = 3 * slot.free.start, 3 * slot.free.stop
            band = restrict_band(terms.hessian_banded, lo, hi)
            pick = lambda a: a.reshape(-1)[lo:hi]  # noqa: E731
        rank1 = None if tw is None or tw.c == 0 else (pick(tw.g), float(tw.c))
        return band, rank1, pick(terms.grad_x)

    def _unconstrained(self, system: ImplicitSystem, grad: np.ndarray, v: np.ndarray):
        """The implicit step without contact: (end-of-step acceleration a0 [m/s^2], the
        non-elastic force on the rod dofs [N]: gravity plus the user's xfrc_applied)."""
        d = self._data
        user = d.xfrc_applied[self._free_bodies, :3].ravel()
        other = (self._mass.reshape(-1, 3) * self._model.opt.gravity).ravel() + user
        return system.solve(system.rhs(other - grad, v)), other

    def _projection_step(self, system: ImplicitSystem, grad: np.ndarray, v: np.ndarray) -> None:
        """Implicit bending/twist step, then fast projection onto the rest edge lengths."""
        from .projection import project

        m, d = self._model, self._data
        h = m.opt.timestep
        dofs, mass = self._dofs, self._mass
        a0, other = self._unconstrained(system, grad, v)
        accel = np.empty_like(a0)
        for i, slot in enumerate(self._slots):
            lo, hi = self._offsets[i], self._offsets[i + 1]
            x = self._positions(slot)
            inv_mass = np.zeros(slot.rod.n_vertices)
            inv_mass[slot.free] = 1.0 / slot.mass[0::3]
            pred = x.copy()
            v_rod = v[lo:hi].reshape(-1, 3)
            pred[slot.free] += h * (v_rod + h * a0[lo:hi].reshape(-1, 3))
            xp, _ = project(pred, inv_mass, slot.rod.rest_len)
            accel[lo:hi] = (((xp[slot.free] - x[slot.free]) / h - v_rod) / h).ravel()
        d.qfrc_applied[dofs] = mass * accel - other
        mujoco.mj_step(m, d)

    def _implicit_step(self, system: ImplicitSystem, grad: np.ndarray, v: np.ndarray) -> None:
        """One implicit step: unconstrained solve, MuJoCo's forward pass (contacts and
        the rest of the scene), contacts re-solved in the implicit metric, integration."""
        m, d = self._model, self._data
        dofs, mass = self._dofs, self._mass
        a0, other = self._unconstrained(system, grad, v)
        # With this force MuJoCo's unconstrained acceleration of the rod dofs is a0, so
        # its own constraint solve (for bodies the rods touch) sees the implicit motion.
        d.qfrc_applied[dofs] = mass * a0 - other
        mujoco.mj_checkPos(m, d)
        mujoco.mj_checkVel(m, d)
        mujoco.mj_forward(m, d)
        rows, external = contact.rod_rows(m, d, self._local_of_dof, system.n)
        self._contact = external
        if rows is not None or np.any(external):
            a = a0 if not np.any(external) else a0 + system.solve(external)
            if rows is not None:
                rows.rescale(system)
                a, lam, _ = contact.solve(system, a, rows)
                self._contact = external + rows.transpose_apply(lam, system.n)
            d.qacc[dofs] = a
            if m.opt.integrator != mujoco.mjtIntegrator.mjINT_EULER:
                # mj_implicit re-solves from forces; our dofs carry no damping or coupling
                # there, so this force reproduces acceleration a.
                d.qfrc_constraint[dofs] = mass * a - d.qfrc_smooth[dofs]
        mujoco.mj_checkAcc(m, d)
        if m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER:
            mujoco.mj_Euler(m, d)
        else:
            mujoco.mj_implicit(m, d)

    def _fail(self, slot_name: str, what: str) -> None:
        h = self._model.opt.timestep
        hint = (f"try a smaller dt (now {h:g} s)"
                + ("" if self.mode == "implicit" else ", mode='implicit'")
                + f", or more damping (mass_damping now {self.mass_damping:g} 1/s)")
        raise DivergenceError(
            f"rod '{slot_name}' diverged at step {self.n_steps} (t = {self._data.time:.6g} s): {what}; {hint}"
        )

    def _check_strain(self, slot: _Slot, x: np.ndarray) -> None:
        e = _edges(x, slot.rod.closed)
        strain = np.max(np.abs(np.sqrt(np.einsum("ij,ij->i", e, e)) / slot.rod.rest_len - 1.0))
        if not np.isfinite(strain) or strain > MAX_STRAIN:
            self._fail(slot.name, f"edge strain {strain:.3g} exceeds {MAX_STRAIN:g}")

    def _check_divergence(self, dofs: np.ndarray) -> None:
        d = self._data
        n_bad = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
        if n_bad != self._badqacc:
            self._badqacc = n_bad
            self._fail(self._slot_of_dof(None), "MuJoCo reported bad accelerations (BADQACC) and reset the state")
        v = d.qvel[dofs]
        speed = np.max(np.abs(v))  # NaN if any entry is NaN
        if not speed <= MAX_SPEED:
            if not np.all(np.isfinite(v)):
                self._fail(self._slot_of_dof(int(np.flatnonzero(~np.isfinite(v))[0])), "NaN or infinite state")
            self._fail(self._slot_of_dof(int(np.argmax(np.abs(v)))),
                       f"vertex speed {speed:.3g} m/s exceeds {MAX_SPEED:g}")

    def _slot_of_dof(self, k: int | None) -> str:
        if k is None or len(self._slots) == 1:
            return self._slots[0].name if len(self._slots) == 1 else "?"
        i = int(np.searchsorted(self._offsets, k, side="right") - 1)
        return self._slots[i].name
