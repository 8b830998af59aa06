"""The backends of the comparison harness, behind one small protocol.

Every benchmark case (:mod:`derods.bench.cases`) drives a rod through
:class:`RodSimulator` only: derods' :class:`~derods.sim.world.World` implements
it as it is, MuJoCo's native rods through :mod:`derods.bench.native` (flexcomp)
and :mod:`derods.bench.cable` (MuJoCo 3.x's cable). What differs between
backends, how each builds a clamped, free or twisted rod and how it applies an
end couple, lives in one :class:`Backend` record per backend, not in the cases.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import mujoco
import numpy as np

from .. import scenes, shapes
from ..rod import Rod
from ..sim.world import ContactParams, World
from ..twist import TwistBoundary
from . import cable, elastica, native


class RodSimulator(Protocol):
    """What a benchmark case needs from a simulator of one rod (every backend here runs in
    MuJoCo, so ``model`` and ``data`` are MuJoCo's). ``rod`` names or indexes the rod in
    a world of several (a native model holds one and ignores it)."""

    model: mujoco.MjModel
    data: mujoco.MjData

    @property
    def time(self) -> float: ...

    @property
    def n_steps(self) -> int: ...

    @property
    def active_terms(self) -> dict: ...

    def step(self, n_steps: int = 1) -> None: ...

    def positions(self, rod=0) -> np.ndarray: ...

    def velocities(self, rod=0) -> np.ndarray: ...

    def set_positions(self, rod, x: np.ndarray) -> None: ...

    def set_velocities(self, rod, v: np.ndarray) -> None: ...

    def dofs(self, rod=0) -> np.ndarray: ...

    def vertex_body(self, rod, vertex: int) -> int: ...


@dataclass(frozen=True)
class Backend:
    """How one backend builds the benchmark's rods.

    name: "der", "flex", "cable" or "elastica". mode: the record's mode for a run (derods: its
    own mode; the natives: their MuJoCo integrator). requirement: None if this MuJoCo
    runs it, else the message saying how to get it. cantilever(p, gravity, damping):
    a rod clamped at (0, 0, 1) m along +x, with its rest vertices. free_rod(p, x, scene,
    damping): a free rod at x in mjcf/<scene>.xml (None: empty space). twisted_ring(p,
    total_twist, self_contact): Michell's ring (:func:`native.ring_vertices`), no gravity.
    end_couple(sim, moment): apply an end couple [N m] bending the rod upwards, this step.
    """

    name: str
    mode: Callable[[object], str]
    requirement: Callable[[], str | None]
    cantilever: Callable
    clamped_rod: Callable
    free_rod: Callable
    twisted_ring: Callable | None
    end_couple: Callable


# --- derods --------------------------------------------------------------------------------------

def _der_clamped(p, x: np.ndarray, gravity: float, damping: float) -> World:
    """A rod at ``x`` [m] whose first edge is clamped."""
    world = World(dt=p.dt, gravity=(0.0, 0.0, -gravity), mode=p.mode, mass_damping=damping)
    world.add_rod(Rod(x, p.material), "rod", start="clamp")
    world.compile()
    return world


def _der_cantilever(p, gravity: float, damping: float):
    # derods puts the clamp at the middle of the first edge (shapes.cantilever).
    x = shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    return _der_clamped(p, x, gravity, damping), x


def _der_free(p, x: np.ndarray, scene: str | None, damping: float = 0.0) -> World:
    # The stability sweeps drop rods at steps too long for the fall on purpose, to record
    # what happens: the scene checks' warning is not news here.
    world = World(scenes.path(scene) if scene else None, dt=p.dt, gravity=(0.0, 0.0, -p.gravity),
                  mode=p.mode, mass_damping=damping, scene_checks=False)
    world.add_rod(Rod(x, p.material, natural_curvature=False), "rod")
    world.compile()
    return world


def _der_ring(p, total_twist: float, self_contact: bool = False) -> World:
    """derods closes the ring itself (with self-contact if asked)."""
    world = World(dt=p.dt, gravity=(0.0, 0.0, 0.0), mode=p.mode, contact=ContactParams(self_collision=self_contact))
    world.add_rod(Rod(native.ring_vertices(p), p.material, closed=True, natural_curvature=False,
                      boundary=TwistBoundary("ring", total_twist=total_twist)), "ring")
    return world


def _force_pair(sim, moment: float) -> None:
    """A couple on the last edge, in the xz plane, following the edge as it turns: two
    opposite forces at its vertices."""
    x = sim.positions()
    e = x[-1] - x[-2]
    n = len(x) - 1
    force = moment / float(e @ e) * np.array([-e[2], 0.0, e[0]])
    sim.data.xfrc_applied[sim.vertex_body(0, n), :3] = force
    sim.data.xfrc_applied[sim.vertex_body(0, n - 1), :3] = -force


# --- MuJoCo's flexcomp ---------------------------------------------------------------------------

def _flex_clamped(p, x: np.ndarray, gravity: float, damping: float):
    rod, _ = native.flex_rod(x, p, pinned=(0, 1), gravity=(0.0, 0.0, -gravity), mass_damping=damping)
    return rod


def _flex_cantilever(p, gravity: float, damping: float):
    # The native flexcomp pins the first edge of a rod starting at the clamp, as a MuJoCo user would.
    x = shapes.straight(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    return _flex_clamped(p, x, gravity, damping), x


def _flex_free(p, x: np.ndarray, scene: str | None, damping: float = 0.0):
    rod, _ = native.flex_rod(x, p, scene=scene, mass_damping=damping)
    return rod


def _flex_requirement() -> str | None:
    if native.has_flex_elasticity():
        return None
    return (f"backend 'flex' needs MuJoCo >= 3.17 (1D flex elasticity); this is {mujoco.__version__}: "
            "pip install -U mujoco")


# --- MuJoCo 3.x's cable --------------------------------------------------------------------------

def _cable_cantilever(p, gravity: float, damping: float):
    # The cable's own damping (joint damping 0.01 E I / h, implicit) replaces mass damping.
    x = shapes.straight(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    return cable.cable_rod(p, gravity=(0.0, 0.0, -gravity)), x


def _cable_clamped(p, x: np.ndarray, gravity: float, damping: float):
    raise ValueError("a composite cable takes uniform segments along a line: no arbitrary clamped shape")


def _cable_free(p, x: np.ndarray, scene: str | None, damping: float = 0.0):
    return cable.cable_rod(p, clamped=False, start=x[0], direction=x[-1] - x[0], scene=scene)


def _cable_couple(sim, moment: float) -> None:
    """A couple is a torque on the last segment (-y curls the rod upwards)."""
    tip = len(sim.positions()) - 1
    sim.data.xfrc_applied[sim.vertex_body(0, tip), 3:] = (0.0, -moment, 0.0)


def _cable_requirement() -> str | None:
    if cable.has_cable():
        return None
    return (f"backend 'cable' needs MuJoCo 3.x (the cable plugin was removed in 4.0; this is {mujoco.__version__}); "
            "make venv317, then run with .venv317/bin/python")


# --- PyElastica -----------------------------------------------------------------------------------

def _elastica_cantilever(p, gravity: float, damping: float):
    # Started h/2 behind the clamp, as derods' rod (see derods.bench.elastica).
    x = shapes.cantilever(p.length, p.n_edges, start=(0.0, 0.0, 1.0))
    return elastica.ElasticaRod(x, p.material, p.dt, gravity, damping), x


def _elastica_free(p, x: np.ndarray, scene: str | None, damping: float = 0.0):
    if scene:
        raise ValueError("the elastica backend has no MuJoCo scene to put a rod in")
    return elastica.ElasticaRod(x, p.material, p.dt, p.gravity, damping, clamped=False)


def _elastica_unsupported(*args, **kwargs):
    raise ValueError("the elastica backend runs straight rods only, clamped or free (see derods.bench.elastica)")


BACKENDS = {
    "der": Backend("der", lambda p: p.mode, lambda: None, _der_cantilever, _der_clamped, _der_free, _der_ring,
                   _force_pair),
    "flex": Backend("flex", lambda p: "discrete", _flex_requirement, _flex_cantilever, _flex_clamped, _flex_free,
                    lambda p, theta, self_contact=False: native.flex_ring(p, theta), _force_pair),
    "cable": Backend("cable", lambda p: "implicitfast", _cable_requirement, _cable_cantilever, _cable_clamped,
                     _cable_free, lambda p, theta, self_contact=False: cable.cable_ring(p, theta), _cable_couple),
    "elastica": Backend("elastica", lambda p: "position_verlet", elastica.available, _elastica_cantilever,
                        _elastica_unsupported, _elastica_free, None, _elastica_unsupported),
}

