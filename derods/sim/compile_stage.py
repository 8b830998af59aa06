"""The compile stage of a World: from the scene's spec and the added rods to a model and a step.

:meth:`derods.sim.world.World.compile` runs these in order: the rods added to the spec
(:func:`rods_to_spec`, see :mod:`~derods.sim.layout`), MuJoCo's compile
(:func:`mujoco_model`), the rods' starting state (:func:`starting_state`: the data, the
layout, the rods at rest in their Bishop frames with their twist solved, and what holds
their ends), the mode "auto" resolves to (:func:`pick_mode`) and whether MuJoCo's
integrator allows it (:func:`check_integrator`), the step of that mode
(:func:`make_step`), and what the scene checks find, in words (:func:`scene_report`).
"""

from __future__ import annotations

import sys
import warnings

import mujoco
import numpy as np

from .. import frames
from .. import validation
from ..rod import RodState
from ..step import Frames, RodSet
from .alpha_step import GeneralizedAlpha
from .clamps import end_bodies
from .exclusion import Exclusions, SelfReach, self_reach
from .integrators import Explicit, Implicit
from .layout import PROGRESS_FROM, Layout, RodEntry, add_to_spec
from .projection_step import Projection
from .scene_checks import fall_step, starts_inside, stretched_words, thin_geoms
from .speculative import SpeedMargin

#: The step of each mode but "auto" (which picks one of them).
STEPS = {"explicit": Explicit, "implicit": Implicit, "projection": Projection, "alpha": GeneralizedAlpha}


def rods_to_spec(spec: mujoco.MjSpec, entries: list[RodEntry], contact) -> None:
    """Add the rods to ``spec`` (``contact``: the World's
    :class:`~derods.sim.contact_params.ContactParams`)."""
    # Rods touch the scene's colliding geoms, and one another when there are several:
    # two rods crossing in an empty world collide too.
    collide = (any(g.contype or g.conaffinity for g in spec.geoms)
               or (contact.rod_rod and len(entries) > 1))
    add_to_spec(spec, entries, contact, collide)


def mujoco_model(spec: mujoco.MjSpec, entries: list[RodEntry]) -> mujoco.MjModel:
    """MuJoCo's compile of ``spec`` (the rods in it), saying so on stderr when it is large."""
    n_vertices = sum(e.rod.n_vertices for e in entries)
    if n_vertices > PROGRESS_FROM:
        print(f"compiling the MuJoCo model ({n_vertices} rod vertices)...", file=sys.stderr, flush=True)
    with warnings.catch_warnings():
        # Our flexes carry no MuJoCo elasticity by design: derods supplies it.
        warnings.filterwarnings("ignore", message=".*has no equality constraints or passive forces")
        # Rod chunks are attached with their names as they are (see layout._attach).
        warnings.filterwarnings("ignore", message=".*empty prefix may prevent the model")
        return spec.compile()


def starting_state(model: mujoco.MjModel, entries: list[RodEntry]):
    """The compiled world before its first step: ``(data, layout, rods, frames, ends)``,
    the data forwarded, the rods (a :class:`derods.step.RodSet`) at rest in their Bishop
    frames with their twist solved, and their held ends (:func:`derods.sim.clamps.end_bodies`)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # positions of every body
    layout = Layout.build(model, entries)
    rods = RodSet.of([e.rod for e in entries])
    # The rods start at rest in their Bishop frames, twist solved.
    states = []
    for e in entries:
        t = frames.tangents(e.x0, e.rod.closed)
        start = RodState(e.x0.copy(), frames.bishop_frames(e.x0, e.rod.closed, e.rod.u0), t, np.zeros(len(t)))
        states.append(e.rod.advance(start, e.x0))
    fr = Frames.of(states)
    ends = end_bodies(model, data, entries, fr.u, fr.t, fr.theta, rods.e_off, fr.theta_end)
    return data, layout, rods, fr, ends


def pick_mode(requested_mode: str, h: float, dt_limit: float) -> str:
    """The mode a World steps in: the one requested, or for "auto", "implicit" when the
    step ``h`` [s] exceeds half the explicit stability limit ``dt_limit`` [s], else "explicit"."""
    if requested_mode == "auto":
        return "implicit" if h > 0.5 * dt_limit else "explicit"
    return requested_mode


def check_integrator(model: mujoco.MjModel, mode: str) -> None:
    """Refuse an implicit or alpha step under a MuJoCo integrator it cannot follow."""
    supported = (mujoco.mjtIntegrator.mjINT_EULER, mujoco.mjtIntegrator.mjINT_IMPLICIT,
                 mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
    if mode in ("implicit", "alpha") and model.opt.integrator not in supported:
        name = mujoco.mjtIntegrator(model.opt.integrator).name
        raise validation.InvalidInputError(
            f"integrator: the implicit rod step needs MuJoCo's Euler, implicit or implicitfast integrator, "
            f"the scene uses {name}; pass integrator='implicitfast' to World"
        )


def make_step(mode: str, model, data, layout, entries, rods, fr, ends, mass_damping: float,
              stiffness_damping: float, diagnosis, strain_limit: float | None, contact, excludes=()):
    """The step of ``mode`` (:data:`STEPS`), with the World's strain limit (None keeps the
    step's default), what of its :class:`~derods.sim.contact_params.ContactParams` the
    step reads (whether held edges touch their holders, static friction) and the contacts
    it excludes (:class:`derods.sim.exclusion.ExcludedPair`, and with self-collision each
    thick rod's self-contacts nearer than pi r along it, :func:`derods.sim.exclusion.self_reach`:
    where the mode runs MuJoCo's forward pass in stages, the implicit and alpha modes; the
    others warn)."""
    step = STEPS[mode](model, data, layout, entries, rods, fr, ends, mass_damping, stiffness_damping, diagnosis)
    reaches = [SelfReach(e.name, reach, e.rod.n_edges, e.rod.closed) for e in entries if contact.self_collision
               for reach in [self_reach(e.rod.material.radius, e.rod.rest_len)] if reach > 1]
    staged = getattr(step, "forward", None) is not None and (mode != "projection" or step.holders)
    if excludes or reaches:
        if staged:
            step.forward.exclusions = Exclusions(model, list(excludes), reaches)
        elif excludes:
            warnings.warn(f"mode {mode!r} steps with mj_step, which cannot leave out contacts between a rod's end "
                          f"edges and a body (the file's contact excludes naming B_first or B_last): they collide; "
                          "mode 'implicit' (the default) or 'alpha' honour them", validation.SceneWarning,
                          stacklevel=4)
        else:
            warnings.warn(f"mode {mode!r} steps with mj_step, which cannot leave out a thick rod's self-contacts "
                          f"between edges closer along it than pi r ({', '.join(r.rod for r in reaches)}): they "
                          "push as if the rod were stiffer; mode 'implicit' (the default) or 'alpha' leave them out",
                          validation.SceneWarning, stacklevel=4)
    if strain_limit is not None:
        step.strain_limit = strain_limit
    if getattr(step, "coupled", None) is not None:
        step.coupled.holder_contact = contact.holder_contact
    if getattr(step, "friction", None) is not None and not contact.static_friction:
        step.friction.enabled = False
    fast = speculative_rods(contact.speculative, step, len(entries))
    if len(fast):
        if staged:
            rod_of_place = np.searchsorted(layout.v_off, layout.free_vertex, side="right") - 1
            step.speculative = SpeedMargin(model, step.rod_flex, rod_of_place, contact.margin, fast)
            step.reference.margin = True
            step.reference.sink = step.speculative.sink
        elif contact.speculative:
            warnings.warn(f"mode {mode!r} steps with mj_step, whose solver reads a contact margin as a skin to rest "
                          "on: speculative contacts are left out; mode 'implicit' (the default) or 'alpha' take "
                          "them", validation.SceneWarning, stacklevel=4)
    return step


def speculative_rods(speculative: bool | None, step, n_rods: int) -> np.ndarray:
    """The rods whose contact margins follow their speed (:mod:`derods.sim.speculative`):
    every rod (``speculative`` True), none (False), or (None, the default) the rods held by
    bodies with dofs (:class:`~derods.sim.contact_params.ContactParams`)."""
    if speculative is None:
        holders = getattr(step, "holders", None)
        return holders.rods if holders else np.zeros(0, dtype=np.int64)
    return np.arange(n_rods) if speculative else np.zeros(0, dtype=np.int64)


def scene_report(spec: mujoco.MjSpec, m: mujoco.MjModel, d: mujoco.MjData, entries: list[RodEntry],
                 excess: dict) -> list:
    """What :mod:`derods.sim.scene_checks` finds in this compiled world, in words."""
    out = []
    if any(g.contype or g.conaffinity for g in spec.geoms):
        # Only rods with no end held can fall.
        free = [e for e in entries if e.start == "free" and e.end == "free"]
        if free:
            tops = [float(e.x0[:, 2].max()) for e in free]
            fall = fall_step(m, d, tops, [float(e.rod.length) for e in free])
            if fall is not None:
                out.append(fall)
            else:
                radius = min(e.rod.material.radius for e in free)
                out += thin_geoms(m, d, tops, radius)
        holders = [[m.body(b).id for b in (e.start_body, e.end_body) if b] for e in entries]
        out += starts_inside(m, d, [e.name for e in entries], [e.rod.material.radius for e in entries], holders)
    return out + stretched_words(entries, excess)
