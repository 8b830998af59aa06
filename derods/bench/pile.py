"""The pile benchmark: many cables dropped into a heap on the floor, touching the floor, one
another and themselves, with friction (``derods bench pile``); what a simulated frame of
1/60 s costs.

The cables (``cables`` of ``vertices`` each, 1 cm edges, radius 5 mm, E = 1e7 Pa, 1000
kg/m^3) start straight in horizontal layers of ceil(sqrt(cables)) parallel cables 3 cm
apart, each layer turned by 2.4 rad from the one below and 2.5 diameters above it, the
lowest 5 cm above the floor (mjcf/floor.xml), and fall from rest. derods' contacts: rods
with the floor, rod with rod and each rod with itself (``ContactParams(self_collision=True)``),
friction 1 (a cable's edges nearer along it than pi r do not touch:
:func:`derods.sim.exclusion.self_reach`), contact margin ``margin`` (or margins sized by
each cable's speed: ``speculative``), implicit steps of ``dt`` with mass damping 1/s.

The same pile runs on MuJoCo's native rods (``backend="flex"``): one 1D flexcomp a cable
(MuJoCo's own elasticity, the discrete integrator, MuJoCo's own contact solver at its
defaults), the same material, friction, contact parameters and mass damping; no margins,
and no self-contact (MuJoCo's own would press every straight cable's edges two apart,
which derods leaves out), which spares the flex work derods does.

A record holds ``backend``, ``cables``, ``vertices``, ``dt``, ``seconds``; ``build_s`` [s]
(scene and cables to a compiled model); ``steps``, ``wall_s`` [s] (the steps alone), ``cpu_s`` [s]
(this process's CPU time in them: on a shared machine, well below wall_s when other work
competes for the cores),
``us_per_step`` [us] (median step), ``mean_us_per_step``, ``ms_per_frame`` [ms] (the
median step times the steps in 1/60 s), ``mean_ms_per_frame`` and ``late_ms_per_frame``
(the median step of the run's second half, the heap formed: free fall is cheap, landing
dear, so a run's median mixes the phases); ``stable``; ``penetration`` [m], the deepest
contact (rod in floor, rod in rod) over the second half, and ``penetration_max`` over the
whole run (a run stopped before its second half has None for the late figures); ``contacts`` at the end;
``heap_height`` [m], the highest vertex at the end; ``max_speed`` [m/s] at the end;
``solver_iterations`` (flex: the median and largest of MuJoCo's solver iterations a step,
and the steps that ended at its cap, unconverged; None for derods, whose contact solve
runs to its tolerance).
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from .. import scenes, shapes
from ..material import Material
from ..rod import Rod
from ..sim.contact_params import ContactParams
from ..sim.divergence import DivergenceError
from ..sim import layout as layout_mod
from ..sim.world import World
from . import native
from .measures import over_budget
from .params import CaseParams

#: One simulated frame [s]: the cost reported is per frame.
FRAME = 1.0 / 60.0
#: Edge length [m] and radius [m] of the cables.
EDGE, RADIUS = 0.01, 0.005
#: Distance between neighbouring cables of a layer, and between layers [m].
SPACING, LAYER_GAP = 0.03, 5 * RADIUS
#: How far each layer turns from the one below [rad].
LAYER_TURN = 2.4
#: Backends the pile runs on.
PILE_BACKENDS = ("der", "flex")
#: MuJoCo's constraint solvers the flex pile may take.
FLEX_SOLVERS = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG,
                "pgs": mujoco.mjtSolver.mjSOL_PGS}
#: What a record should say about its backend.
NOTES = {"der": "", "flex": "flexcomps without self-contact (derods' cables touch themselves too)"}
#: Mass damping of the cables [1/s].
MASS_DAMPING = 1.0


@dataclass(frozen=True)
class PileCase:
    """cables, vertices: the cables and their vertices each; dt [s]; seconds [s]
    simulated; young [Pa]; friction (sliding coefficient); margin [m]: the cables' contact
    margin (speculative contacts, :class:`derods.sim.contact_params.ContactParams`; 0:
    a cable landing at 1.2 m/s, 10 mm a step, is found up to 2 r inside another);
    speculative: margins sized by each cable's speed instead
    (``ContactParams(speculative=True)``: no deeper than ~0.6 mm once the heap formed, about
    the cost of margin 0 a frame, docs/performance.md); max_wall_s:
    stop stepping once the steps took this long [s] (the record then says so, and covers
    the steps made); backend: "der" or "flex" (MuJoCo's 1D flexcomps, see the module
    docstring; margin 0, no speculative contacts); flex_solver: MuJoCo's constraint solver
    for the flex pile, one of FLEX_SOLVERS (its default, Newton; "cg" stops at its iteration
    cap, unconverged, on a heap)."""

    cables: int = 100
    vertices: int = 41
    dt: float = 1.0 / 120.0
    seconds: float = 2.0
    young: float = 1e7
    friction: float = 1.0
    margin: float = 0.0
    speculative: bool = False
    max_wall_s: float | None = None
    backend: str = "der"
    flex_solver: str = "newton"

    def __post_init__(self):
        if self.flex_solver not in FLEX_SOLVERS:
            raise ValueError(f"flex_solver must be one of {tuple(FLEX_SOLVERS)}, got {self.flex_solver!r}")
        if self.flex_solver != "newton" and self.backend != "flex":
            raise ValueError("flex_solver is the flex pile's option (derods solves its contacts itself)")
        if self.backend not in PILE_BACKENDS:
            raise ValueError(f"backend must be one of {PILE_BACKENDS} for the pile case, got {self.backend!r}")
        if self.backend != "der" and (self.margin or self.speculative):
            raise ValueError("margin and speculative are derods' contact options: the flex pile runs with neither")
        if int(self.cables) != self.cables or self.cables < 1:
            raise ValueError(f"cables must be an integer >= 1, got {self.cables!r}")
        if int(self.vertices) != self.vertices or self.vertices < 3:
            raise ValueError(f"vertices must be an integer >= 3, got {self.vertices!r}")
        for name, unit in (("dt", "s"), ("seconds", "s"), ("young", "Pa")):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be finite and > 0 [{unit}], got {getattr(self, name)!r}")
        if not self.friction >= 0:
            raise ValueError(f"friction must be >= 0, got {self.friction!r}")
        if not (np.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"margin must be finite and >= 0 [m], got {self.margin!r}")
        if not isinstance(self.speculative, (bool, np.bool_)):
            raise ValueError(f"speculative must be True or False, got {self.speculative!r}")

    @property
    def material(self) -> Material:
        return Material(young=self.young, density=1000.0, radius=RADIUS, poisson=0.5)


def layout(case: PileCase) -> list[np.ndarray]:
    """The cables' starting vertices [m], one (vertices, 3) array each (see the module docstring)."""
    per_layer = math.ceil(math.sqrt(case.cables))
    length = EDGE * (case.vertices - 1)
    out = []
    for k in range(case.cables):
        layer, i = divmod(k, per_layer)
        turn = LAYER_TURN * layer
        along = np.array([math.cos(turn), math.sin(turn), 0.0])
        across = np.array([-along[1], along[0], 0.0])
        centre = (i - 0.5 * (per_layer - 1)) * SPACING * across + (0.0, 0.0, 0.05 + LAYER_GAP * layer)
        out.append(shapes.straight(length, case.vertices - 1, start=centre - 0.5 * length * along, direction=along))
    return out


def build(case: PileCase) -> World:
    """The compiled world of ``case``."""
    contact = ContactParams(friction=case.friction, self_collision=True, margin=case.margin,
                            speculative=bool(case.speculative))
    world = World(scenes.path("floor"), dt=case.dt, gravity=(0.0, 0.0, -9.81), mode="implicit",
                  mass_damping=MASS_DAMPING, contact=contact, scene_checks=False)
    mat = case.material
    for k, x in enumerate(layout(case)):
        world.add_rod(Rod(x, mat, natural_curvature=False), f"cable{k}")
    world.compile()
    return world


def build_flex(case: PileCase) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The same cables as MuJoCo flexcomps on the same floor (see the module docstring):
    model and data."""
    mat = case.material
    p = CaseParams(n_edges=case.vertices - 1, dt=case.dt, young=mat.young, poisson=mat.poisson,
                   length=EDGE * (case.vertices - 1), radius=mat.radius, density=mat.density, gravity=9.81,
                   backend="flex")
    n = case.cables * case.vertices
    # MuJoCo's own arena guess grows as nv^2; the budget derods gives its large worlds,
    # doubled for the flex solver's M + K (as the hair's flexcomps).
    memory = 2 * layout_mod.arena_budget(4 * n, n + 2 * case.cables + 64)
    return native.flex_world(layout(case), p, scene="floor", mass_damping=MASS_DAMPING, friction=case.friction,
                             memory=memory)


class _DerPile:
    """derods' pile behind the few calls the run needs."""

    def __init__(self, case: PileCase):
        self.world = build(case)
        self.data = self.world.data
        self.cables = case.cables

    def step(self) -> None:
        self.world.step()

    def positions(self) -> np.ndarray:
        return np.concatenate([self.world.positions(r) for r in range(self.cables)])

    def max_speed(self) -> float:
        return float(max(np.linalg.norm(self.world.velocities(r), axis=1).max() for r in range(self.cables)))

    def solver_iterations(self) -> None:
        """None: derods' contact solve runs to its tolerance."""
        return None


class _FlexPile:
    """The pile as MuJoCo flexcomps (:func:`build_flex`), stepped by mj_step."""

    def __init__(self, case: PileCase):
        self.model, self.data = build_flex(case)
        m = self.model
        m.opt.solver = FLEX_SOLVERS[case.flex_solver]
        bodies = m.flex_vertbodyid[:m.nflexvert]
        self._vertex_dofs = (m.body_dofadr[bodies][:, None] + np.arange(3)).ravel()
        self._steps = native.CheckedSteps(m, self.data, self._vertex_dofs, "native flex pile")
        self._iterations = []

    def step(self) -> None:
        self._steps.step()
        self._iterations.append(int(self.data.solver_niter[0]))

    def positions(self) -> np.ndarray:
        return self.data.flexvert_xpos.copy()

    def max_speed(self) -> float:
        return float(np.linalg.norm(self.data.qvel[self._vertex_dofs].reshape(-1, 3), axis=1).max())

    def solver_iterations(self) -> dict | None:
        """MuJoCo's solver iterations over the steps made (None before the first)."""
        its = self._iterations
        if not its:
            return None
        cap = int(self.model.opt.iterations)
        return {"median": float(np.median(its)), "max": int(max(its)), "at_cap": int(sum(i >= cap for i in its)),
                "cap": cap, "solver": mujoco.mjtSolver(self.model.opt.solver).name.removeprefix("mjSOL_").lower()}


def _deepest(data) -> float:
    """The deepest contact [m] (0 without one; contacts the world left out, a cable's edges
    nearer than pi r along it, do not count)."""
    kept = data.contact.exclude[:data.ncon] == 0
    return float(max(0.0, -np.min(data.contact.dist[:data.ncon][kept]))) if kept.any() else 0.0


def run(case: PileCase, progress=None) -> dict:
    """Build and run ``case``; returns its record. progress: optional ``f(text)``."""
    t0 = time.perf_counter()
    sim = (_DerPile if case.backend == "der" else _FlexPile)(case)
    build_s = time.perf_counter() - t0
    if progress:
        progress(f"built {case.cables} cables x {case.vertices} vertices ({case.backend}) in {build_s:.1f} s")
    n_steps = int(round(case.seconds / case.dt))
    times, pen_late, pen_max, cpu = [], None, 0.0, 0.0
    stable, note, budget = True, "", ""
    try:
        for k in range(n_steps):
            budget = over_budget(k, n_steps, case.dt, sum(times), case.max_wall_s)
            if budget:
                break
            a, c = time.perf_counter(), time.process_time()
            sim.step()
            times.append(time.perf_counter() - a)
            cpu += time.process_time() - c
            pen = _deepest(sim.data)
            pen_max = max(pen_max, pen)
            if k >= n_steps // 2:  # the heap formed
                pen_late = max(pen_late or 0.0, pen)
            if progress and (k + 1) % max(1, n_steps // 20) == 0:
                progress(f"step {k + 1} of {n_steps}: {1e3 * np.median(times):.1f} ms median step, "
                         f"{sum(times):.0f} s wall, {cpu:.0f} s CPU")
        x = sim.positions()
        if not np.all(np.isfinite(x)):
            raise DivergenceError(f"positions not finite after {len(times)} steps")
    except DivergenceError as err:
        stable, note = False, str(err)
    steps_per_frame = FRAME / case.dt
    median = float(np.median(times)) if times else None
    mean = float(np.mean(times)) if times else None
    rec = {
        "case": "pile", "backend": case.backend, "mujoco_version": mujoco.__version__, "cables": case.cables,
        "vertices": case.vertices, "n_edges": case.vertices - 1, "dt": case.dt,
        "mode": "implicit" if case.backend == "der" else "native",
        "seconds": case.seconds, "young": case.young, "friction": case.friction, "margin": case.margin,
        "speculative": bool(case.speculative), "radius": RADIUS,
        "length": EDGE * (case.vertices - 1), "build_s": build_s, "steps": len(times), "sim_s": len(times) * case.dt,
        "wall_s": float(np.sum(times)), "cpu_s": cpu, "us_per_step": None if median is None else 1e6 * median,
        "mean_us_per_step": None if mean is None else 1e6 * mean,
        "ms_per_frame": None if median is None else 1e3 * median * steps_per_frame,
        "mean_ms_per_frame": None if mean is None else 1e3 * mean * steps_per_frame,
        "late_ms_per_frame": (1e3 * float(np.median(times[n_steps // 2:])) * steps_per_frame
                              if len(times) > n_steps // 2 else None),
        "stable": stable, "penetration": pen_late, "penetration_max": pen_max, "contacts": int(sim.data.ncon),
        "heap_height": None, "max_speed": None, "solver_iterations": sim.solver_iterations(),
        "note": "; ".join(t for t in (note or budget, NOTES[case.backend]) if t),
    }
    if stable:
        rec["heap_height"] = float(x[:, 2].max())
        rec["max_speed"] = sim.max_speed()
    return rec


def format_record(rec: dict) -> str:
    """One readable line for a pile record."""
    head = (f"pile {rec.get('backend', 'der')}: {rec['cables']} cables x {rec['vertices']} vertices, "
            f"dt={rec['dt']:.4g}, "
            f"{rec['seconds']:g} s" + (f", margin {rec['margin']:g} m" if rec.get("margin") else "")
            + (", speculative contacts" if rec.get("speculative") else "")
            + f" | build {rec['build_s']:.2f} s")
    if not rec["stable"]:
        return f"{head} | UNSTABLE: {rec['note']}"
    late = (f"{rec['late_ms_per_frame']:.1f} ms per frame in the second half, deepest contact there "
            f"{rec['penetration'] * 1e3:.2f} mm" if rec["late_ms_per_frame"] is not None
            else "stopped before the second half")
    return (f"{head} | {rec['ms_per_frame']:.1f} ms per 1/60 s frame (median step {rec['us_per_step'] / 1e3:.2f} ms; "
            f"mean {rec['mean_ms_per_frame']:.1f}; CPU {rec['cpu_s']:.3g} s of {rec['wall_s']:.3g} s) | {late} | "
            f"deepest contact {rec['penetration_max'] * 1e3:.2f} mm | {rec['contacts']} contacts at the end, heap "
            f"{rec['heap_height'] * 1e3:.0f} mm high, fastest vertex {rec['max_speed']:.2g} m/s"
            + _format_iterations(rec.get("solver_iterations")) + (f" | {rec['note']}" if rec["note"] else ""))


def _format_iterations(its: dict | None) -> str:
    if not its:
        return ""
    return (f" | MuJoCo's {its['solver']} solver: {its['median']:g} iterations a median step, {its['max']} at most, "
            f"{its['at_cap']} steps stopped at its cap of {its['cap']} (unconverged)")


def main(case: PileCase, as_json: bool, stream=None) -> int:
    """Run the pile case and print its record; returns a process exit code."""
    stream = sys.stdout if stream is None else stream
    rec = run(case, progress=None if as_json else (lambda text: print(text, file=sys.stderr, flush=True)))
    print(json.dumps(rec) if as_json else format_record(rec), file=stream, flush=True)
    return 0
