"""A MuJoCo scene with discrete elastic rods in it: the :class:`World` facade.

Add rods, compile, step, read. Behind it, one module per concern:
:mod:`~derods.sim.contact_params` (how rods touch the scene), :mod:`~derods.sim.inputs`
(the modes, the scene read into a spec, each added rod checked and put in shape),
:mod:`~derods.sim.compile_stage` (from the spec and the rods to the model and the step),
:mod:`~derods.sim.layout` (the rods as MuJoCo bodies and where their numbers
live), :mod:`~derods.sim.clamps` (pins and clamps, on the world or on moving
bodies, and their reaction), :mod:`~derods.sim.holders` (bodies with dofs holding
them, solved with the rods), :mod:`~derods.sim.integrators` and
:mod:`~derods.sim.alpha_step` (one step per mode), :mod:`~derods.sim.implicit` and
:mod:`~derods.sim.contact` (the implicit system and contacts in its metric, with the
body trees that touch rods, :mod:`~derods.sim.trees`), :mod:`~derods.sim.divergence`
(what counts as a lost solution), and :mod:`derods.step` (the rods' terms).

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

import time
import warnings

import mujoco
import numpy as np

from .._numba.coupling import gather_positions
from .. import validation
from ..io import mjcf_load
from .rod_contacts import RodContact, rod_contacts
from ..rod import Rod, RodState, check_turns
from . import compile_stage
from .contact_params import ContactParams
from .divergence import Diagnosis, Guard
from .inputs import MIN_VERTEX_MASS, MODES, rod_entry, rod_index, scene_spec, world_options
from .explicit_limit import explicit_dt_limit
from .layout import RodEntry
from .scene_checks import stretched

# ContactParams, MODES and MIN_VERTEX_MASS live in contact_params and inputs; they are
# named here too, where derods and its users have always imported them from.
__all__ = ["MIN_VERTEX_MASS", "MODES", "ContactParams", "World"]


class World:
    """A MuJoCo scene with DER rods in it.

    scene: None for an empty world, a path to an MJCF file, or a ``mujoco.MjSpec``.
    dt: time step [s]; None keeps the scene's (MuJoCo's default 2e-3).
    gravity: [m/s^2], shape (3,); None keeps the scene's.
    mode: "implicit" (linearly implicit backward Euler: unconditionally stable, damps
        a mode of angular frequency w by (1 + (w h)^2)^(-1/2) per step), "alpha"
        (generalized-alpha: as stable for linear systems, second order, keeps resolved
        modes' amplitude and damps unresolved ones by ``rho_inf`` per step; see
        :mod:`derods.sim.generalized_alpha`), "explicit", "auto" (implicit when dt exceeds half the
        estimated explicit stability limit of the stiffest rod), or "projection":
        the DER paper's method, an implicit step for bending and twisting with
        inextensibility enforced by fast projection (:mod:`derods.sim.projection`)
        instead of a stiff stretching term; MuJoCo then resolves contacts with
        the bare vertex masses, as in the explicit mode.
    mass_damping: a [1/s]; stiffness_damping: b [s] (see the module docstring).
    contact: :class:`ContactParams` for all rods.
    integrator: MuJoCo integrator name for a new world ("implicitfast" by default);
        a scene keeps its own unless given.
    strain_limit: the implicit mode's strain limit [relative edge strain]: an open
        rod of the default stretch stiffness whose step would strain an edge beyond it
        is projected back onto its rest lengths (see
        :data:`derods.sim.strain_limit.STRAIN_LIMIT`, the default, 1e-3); ``math.inf``
        turns it off.
    rods_from: which rods a scene file declares are derods': "composite" (default: MuJoCo
        3.x cable composites, ``<composite type="cable">``) or "flexcomp" (1D flexcomps too);
        see :mod:`derods.io.mjcf_load` and docs/mjcf.md.
    scene_checks: at compile, warn (:class:`derods.SceneWarning`) of a step too long for
        the fall or for a thin obstacle, a rod starting inside an obstacle, and a rod
        held at both ends that starts longer than its rest length
        (:mod:`derods.sim.scene_checks`); False silences them.

    Add rods with :meth:`add_rod`, then :meth:`step`. The MuJoCo model is
    compiled on first use and available as :attr:`model` and :attr:`data`.
    Inputs derods cannot simulate are refused with a :class:`derods.InvalidInputError`
    (:mod:`derods.validation`). A step that loses the solution, or that MuJoCo warns
    about (a NaN written into ``data.qvel`` between steps: MuJoCo would restart the world
    from its start), raises :class:`derods.DivergenceError` naming the cause, the world
    put back where the step began (:class:`derods.sim.divergence.Guard`; MuJoCo's
    automatic reset is off in :attr:`model`).
    """

    def __init__(self, scene=None, *, dt: float | None = None, gravity=None, mode: str = "auto",
                 mass_damping: float = 0.0, stiffness_damping: float = 0.0,
                 contact: ContactParams = ContactParams(), integrator: str | None = None,
                 strain_limit: float | None = None, scene_checks: bool = True, rods_from: str = "composite"):
        world_options(scene, dt, gravity, mode, mass_damping, stiffness_damping, contact, integrator,
                                 strain_limit, scene_checks)
        mjcf_load.check_rods_from(scene, rods_from)
        declared = mjcf_load.Declared()
        if scene is not None and not isinstance(scene, mujoco.MjSpec):  # a file, perhaps with rods in it
            scene, declared = mjcf_load.load(str(scene), rods_from)
        self.spec = scene_spec(scene, integrator, dt, gravity)
        self.requested_mode = mode
        self.mass_damping = float(mass_damping)
        self.stiffness_damping = float(stiffness_damping)
        self.contact = contact
        self.strain_limit = strain_limit
        self.scene_checks = scene_checks
        self.compile_times = None
        self._entries: list[RodEntry] = []
        self._model = None
        self._data = None
        self._step = None
        self._guard = None
        self.mode = None
        self.explicit_dt_limit = None
        #: The rods the scene file declares (derods.io.mjcf_load), finished at compile.
        self._declared = declared
        mjcf_load.add_rods(self, self._declared)

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
            raise validation.InvalidInputError("add_rod: add rods before the world is compiled (before the first "
                                               "step, or reading model or data)")
        entry = rod_entry(self.spec, self._entries, self.requested_mode, rod, name, start, end, x, rgba,
                          start_body, end_body)
        self._entries.append(entry)
        return len(self._entries) - 1

    def compile(self) -> None:
        """Build the MuJoCo model and the step (done automatically on first use)."""
        if self._model is not None:
            return
        if not self._entries:
            raise validation.InvalidInputError("the world has no rods; add one with add_rod()")
        t0 = time.perf_counter()
        compile_stage.rods_to_spec(self.spec, self._entries, self.contact)
        mjcf_load.finish_spec(self.spec, self._declared)
        t1 = time.perf_counter()
        model = compile_stage.mujoco_model(self.spec, self._entries)
        mjcf_load.finish_model(model, self._declared)
        t2 = time.perf_counter()
        data, layout, rods, fr, ends = compile_stage.starting_state(model, self._entries)
        self.explicit_dt_limit = explicit_dt_limit(self._entries, layout, rods, fr, ends, data)
        h = model.opt.timestep
        self.mode = compile_stage.pick_mode(self.requested_mode, h, self.explicit_dt_limit)
        compile_stage.check_integrator(model, self.mode)
        excess = stretched(self._entries)
        diagnosis = Diagnosis(layout.names, h, self.mode, self.mass_damping, excess)
        self._step = compile_stage.make_step(self.mode, model, data, layout, self._entries, rods, fr, ends,
                                             self.mass_damping, self.stiffness_damping, diagnosis,
                                             self.strain_limit, self.contact, self._declared.excludes)
        self._step.riders = mjcf_load.riders(model, self._declared, layout, rods, fr)
        self._model, self._data, self._layout = model, data, layout
        self._guard = Guard(model, data, layout, self._step, diagnosis)
        if self.scene_checks:
            for text in compile_stage.scene_report(self.spec, model, data, self._entries, excess):
                warnings.warn(text, validation.SceneWarning, stacklevel=3)
        #: Where compile's time went [s]: adding the rods to the spec, MuJoCo's compile
        #: (its body-dof sparsity sorts a row of all nv dofs by insertion: nv^2 / 2 moves,
        #: ~2 s at 96,000 dofs), and the rest (data, layout, rods, the step).
        self.compile_times = {"rods_to_spec": t1 - t0, "mujoco_compile": t2 - t1,
                              "rest": time.perf_counter() - t2}

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
        return [e.rod for e in self._entries]

    @property
    def rod_names(self) -> list[str]:
        return [e.name for e in self._entries]

    def _index(self, rod) -> int:
        return rod_index(rod, self.rod_names)

    def positions(self, rod: int | str = 0) -> np.ndarray:
        """Vertex positions [m] of a rod, shape (n_vertices, 3)."""
        return self.all_positions()[self._layout.vertices(self._index(rod))]

    def all_positions(self) -> np.ndarray:
        """Vertex positions [m] of every rod, laid end to end, shape (total vertices, 3):
        rod i's are rows ``vertex_offsets[i]:vertex_offsets[i + 1]``."""
        self.compile()
        # From qpos, not xpos: after mj_step, xpos still holds the kinematics of the
        # state *before* the integration, one step behind.
        lay = self._layout
        if lay.moved_vertex.size:
            mujoco.mj_kinematics(self._model, self._data)
        x = np.empty_like(lay.x0)
        gather_positions(lay.x0, self._data.qpos, lay.qpos_adr, lay.free_vertex, self._data.xpos, lay.moved_vertex,
                         lay.moved_body, x)
        return x

    @property
    def vertex_offsets(self) -> np.ndarray:
        """Where each rod's vertices start in :meth:`all_positions`, shape (n_rods + 1,)."""
        self.compile()
        return self._layout.v_off.copy()

    def set_positions(self, rod: int | str, x: np.ndarray) -> None:
        """Move a rod's free vertices to ``x`` [m], shape (n_vertices, 3), at rest.

        Held vertices (pins, clamps) stay where they are; frames are carried along.
        """
        self.compile()
        i = self._index(rod)
        e, lay, d = self._entries[i], self._layout, self._data
        x = validation.finite_array("x", x, e.x0.shape, "m")
        validation.points("x", x, e.rod.closed)
        check_turns("x", x, e.rod.closed)
        places = np.arange(lay.dof_off[i] // 3, lay.dof_off[i + 1] // 3)
        vtx = lay.free_vertex[places]
        for p, v in zip(places, vtx):
            d.qpos[lay.qpos_adr[p]:lay.qpos_adr[p] + 3] = x[v - lay.v_off[i]] - lay.x0[v]
        d.qvel[lay.dofs[3 * places[0]:3 * places[-1] + 3]] = 0.0
        mujoco.mj_forward(self._model, d)
        fr, es = self._step.frames, self._edges(i)
        state = e.rod.advance(RodState(x, fr.u[es], fr.t[es], fr.theta[es]), self.positions(i))
        fr.u[es], fr.t[es], fr.theta[es] = state.u, state.t, state.theta
        self._step.restart()

    def velocities(self, rod: int | str = 0) -> np.ndarray:
        """Vertex velocities [m/s] of a rod, shape (n_vertices, 3) (zero where held)."""
        self.compile()
        i = self._index(rod)
        lay = self._layout
        v = np.zeros((self._entries[i].rod.n_vertices, 3))
        lo, hi = lay.dof_off[i], lay.dof_off[i + 1]
        v[lay.free_vertex[lo // 3:hi // 3] - lay.v_off[i]] = self._data.qvel[lay.dofs[lo:hi]].reshape(-1, 3)
        return v

    def set_velocities(self, rod: int | str, v: np.ndarray) -> None:
        """Set a rod's free vertex velocities [m/s], shape (n_vertices, 3) (held ones ignored)."""
        self.compile()
        i = self._index(rod)
        lay = self._layout
        v = validation.finite_array("v", v, self._entries[i].x0.shape, "m/s")
        lo, hi = lay.dof_off[i], lay.dof_off[i + 1]
        self._data.qvel[lay.dofs[lo:hi]] = v[lay.free_vertex[lo // 3:hi // 3] - lay.v_off[i]].ravel()
        self._step.restart()

    def dofs(self, rod: int | str = 0) -> np.ndarray:
        """MuJoCo dof ids of a rod's free vertices, three per vertex (x, y, z), in the
        solve order (vertex order; a ring's zig-zagged, see :func:`derods.stencil.ring_order`)."""
        self.compile()
        i = self._index(rod)
        return self._layout.dofs[self._layout.dof_off[i]:self._layout.dof_off[i + 1]].copy()

    def vertex_body(self, rod: int | str, vertex: int) -> int:
        """MuJoCo body id of a rod's vertex (to push it through ``data.xfrc_applied``, or to
        find it in ``model``); its name is ``f"{rod_name}_{vertex}"``."""
        self.compile()
        i = self._index(rod)
        nv = self._entries[i].rod.n_vertices
        vertex = validation.integer("vertex", vertex)
        if not -nv <= vertex < nv:
            raise validation.InvalidIndexError(f"vertex {vertex} out of range; rod {self.rod_names[i]!r} has {nv} "
                                               "vertices")
        return int(self._layout.body[self._layout.v_off[i] + vertex % nv])

    def reaction(self, rod: int | str = 0, end: str = "start") -> tuple[np.ndarray, np.ndarray]:
        """What a rod puts on the holder of one of its ends (the world or a body) in the
        last step: the force [N], shape (3,), and the moment [N m], shape (3,), about the
        point the end is held at (a pin's vertex; a clamp's: the middle of its edge), both
        in world frame. A clamp's moment includes the twisting moment the rod resists with.
        From the forces at the start of the step (in the alpha mode, at its last Newton
        iterate). An end that is not held gets zeros.
        """
        self.compile()
        validation.choice("end", end, ("start", "end"))
        i = self._index(rod)
        e, lay = self._entries[i], self._layout
        held = e.held(end)
        force, moment = np.zeros(3), np.zeros(3)
        if len(held) == 0:
            return force, moment
        terms, x = self._step.terms, self._step.x
        v = lay.v_off[i] + held
        point = x[v].mean(axis=0)
        f = -terms.grad[v]
        force = f.sum(axis=0)
        moment = np.cross(x[v] - point, f).sum(axis=0)
        if (e.start if end == "start" else e.end) == "clamp":
            edges = self._edges(i)
            edge = edges.start if end == "start" else edges.stop - 1
            moment -= terms.end_moment[i, 0 if end == "start" else 1] * self._step.frames.t[edge]
        return force, moment

    def contact_force(self, rod: int | str = 0) -> np.ndarray:
        """Contact (constraint) force [N] on each vertex in the last step, shape (n_vertices, 3).

        In the implicit and alpha modes this is the force derods solved for in the step's
        metric (plus MuJoCo's for rows it left to MuJoCo); in explicit mode, MuJoCo's.
        """
        self.compile()
        i = self._index(rod)
        lay = self._layout
        lo, hi = lay.dof_off[i], lay.dof_off[i + 1]
        out = np.zeros((self._entries[i].rod.n_vertices, 3))
        solved = self.mode in ("implicit", "alpha")
        f = self._step.contact_force[lo:hi] if solved else self._data.qfrc_constraint[lay.dofs[lo:hi]]
        out[lay.free_vertex[lo // 3:hi // 3] - lay.v_off[i]] = f.reshape(-1, 3)
        return out

    def contacts(self) -> list[RodContact]:
        """The rods' contacts in the last step, one :class:`~derods.sim.rod_contacts.RodContact`
        each: which vertex or edge touches which body, geom or rod, where, and the normal and
        friction force [N] on the rod (MuJoCo's ``mj_contactForce`` of the row forces the step
        applied: derods' own in the implicit and alpha modes)."""
        self.compile()
        m = self._model
        flex_rod = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, e.name): e.name for e in self._entries}
        return rod_contacts(m, self._data, flex_rod)

    def solved_bodies(self) -> list[str]:
        """The bodies with dofs whose motion derods solved with the rods in the last step (their
        trees touched a rod, or hold one; implicit and alpha modes), by name (or id if unnamed):
        their contact and constraint forces are derods', the rest MuJoCo's."""
        self.compile()
        contact = getattr(self._step, "contact", None)
        if contact is None or self.mode == "projection" and not self._step.holders:
            return []
        m = self._model
        joined = np.isin(m.body_treeid, contact.joined_trees) & (m.body_treeid >= 0)
        joined[self._layout.body] = False  # the rods' own vertex bodies (a held one rides its holder)
        return [m.body(int(b)).name or str(int(b)) for b in np.flatnonzero(joined)]

    def _edges(self, i: int) -> slice:
        e_off = self._step.rods.e_off
        return slice(int(e_off[i]), int(e_off[i + 1]))

    def rod_state(self, rod: int | str = 0) -> RodState:
        """The rod's current :class:`RodState` (frames and twist of the last step), a copy."""
        self.compile()
        i = self._index(rod)
        fr, es = self._step.frames, self._edges(i)
        return RodState(self._step.x[self._layout.vertices(i)].copy(), fr.u[es].copy(), fr.t[es].copy(),
                        fr.theta[es].copy())

    @property
    def active_terms(self) -> dict[str, tuple[str, ...]]:
        """The energy terms each rod evaluates, by rod name."""
        return {e.name: e.rod.active_terms for e in self._entries}

    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def n_steps(self) -> int:
        """Steps taken since compile."""
        return self._step.n_steps if self._step is not None else 0

    # -- stepping ------------------------------------------------------------
    def step(self, n_steps: int = 1) -> None:
        """Advance ``n_steps`` steps of ``model.opt.timestep``.

        Raises :class:`derods.DivergenceError` if a step loses the solution or MuJoCo
        would read a NaN or huge value written between steps: the world is then back where
        that step began (see :class:`derods.sim.divergence.Guard`).
        """
        if type(n_steps) is not int or n_steps < 0:
            n_steps = validation.integer("n_steps", n_steps, ge=0)
        self.compile()
        step, guard, riders = self._step.step, self._guard, self._step.riders
        for _ in range(n_steps):
            guard.before()
            try:
                step()
            except Exception as err:  # undone, and named if a bad value written between steps caused it
                guard.failed(err)
            guard.after()
        if riders and n_steps:
            riders.after_step(self._step.positions(), self._step.frames, self._data)

