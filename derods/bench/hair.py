"""The hair benchmark: R curled strands on a moving head, in derods or in MuJoCo's native
flexcomps, timed and judged the same way (``derods bench hair``).

A record holds, besides the rod parameters the other cases record: ``strands``,
``vertices``, ``motion``; ``build_s`` [s] (scene and strands to a compiled model and its
first forward pass) and ``mujoco_compile_s`` [s], the part of it in MuJoCo's compile; ``us_per_step`` [us] (mean over the run) and ``median_us_per_step``;
``stable``; ``penetration`` [m], the deepest any strand went into the skull after the
impact transients (from half a second after the head starts moving), and
``penetration_max`` [m] over the whole run; ``max_strain`` over the run; ``root_drift``
[m] at the end; ``inertia_warnings``, how often MuJoCo found its inertia (for a
flexcomp, M + K) singular or its solve not converged.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from .. import hair as hair_mod
from .. import scenes
from ..sim import layout
from ..sim.divergence import DivergenceError
from .measures import over_budget
from . import native

#: Backends the hair case runs on.
HAIR_BACKENDS = ("der", "flex")
#: What a record should say about its backend.
NOTES = {"der": "", "flex": ("flexcomp pins belong to the flexcomp's parent body, so the strands are children of "
                             "the mocap head: MuJoCo carries them along with its motion, without the inertia "
                             "that makes derods' strands swing after it")}
#: Penetration counts from this long [s] after the head starts to move (impacts first).
TRANSIENT = 0.5


@dataclass(frozen=True)
class HairCase:
    """strands, vertices: the hair (the rest of :class:`derods.hair.Hair` at its
    defaults); dt [s]; motion: head motion; seconds [s] simulated; backend: "der" or
    "flex" (MuJoCo's 1D flexcomp, one per strand, pinned to the head); strand_contact:
    strands touch one another too (derods only); max_wall_s: stop stepping once the steps
    took this long [s] (the record then says so, and covers the steps made)."""

    strands: int = 1000
    vertices: int = 32
    dt: float = 1e-2
    motion: str = "shake"
    seconds: float = 1.5
    backend: str = "der"
    strand_contact: bool = False
    max_wall_s: float | None = None

    def __post_init__(self):
        if self.backend not in HAIR_BACKENDS:
            raise ValueError(f"backend must be one of {HAIR_BACKENDS} for the hair case, got {self.backend!r}")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be finite and > 0 [s], got {self.dt!r}")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds must be finite and > 0 [s], got {self.seconds!r}")
        hair_mod.Motion(self.motion)
        self.hair  # checks strands and vertices
        if self.strand_contact and self.backend != "der":
            raise ValueError("strand_contact is derods' option (the flexcomp hair has none)")

    @property
    def hair(self) -> hair_mod.Hair:
        return hair_mod.Hair(strands=self.strands, vertices=self.vertices)


class _DerHair:
    """derods' hair behind the few calls the run needs."""

    def __init__(self, case: HairCase):
        self.world = hair_mod.build(case.hair, dt=case.dt, strand_contact=case.strand_contact)
        self.world.compile()
        self.model, self.data = self.world.model, self.world.data
        self.mujoco_compile_s = self.world.compile_times["mujoco_compile"]
        self.drive = hair_mod.drive(self.world, hair_mod.Motion(case.motion))

    def step(self):
        self.drive(self.world)
        self.world.step()

    def positions(self) -> np.ndarray:
        return hair_mod.strand_positions(self.world)


class _FlexHair:
    """The same strands as native flexcomps: each one's first two vertices pinned to the
    head body (they ride on it), MuJoCo's own flex elasticity, the same mass damping."""

    def __init__(self, case: HairCase):
        h = case.hair
        spec = mujoco.MjSpec.from_file(str(scenes.path(hair_mod.SCENE)))
        spec.option.timestep = case.dt
        # MuJoCo integrates flex elasticity implicitly only in its "discrete" integrator.
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
        head = spec.body(hair_mod.HEAD)
        centre = np.asarray(head.pos, float)
        mat = h.material
        nu, _ = native.poisson_for(mat.young, mat.shear_modulus)
        for k, x in enumerate(hair_mod.strands(h, centre, float(spec.geom(hair_mod.SKULL).size[0]))):
            mass = mat.density * math.pi * mat.radius ** 2 * h.length
            child = native.flex_spec(x - centre, mat.radius, mass, mat.young, nu, pinned=(0, 1), dt=case.dt,
                                     gravity=spec.option.gravity, holder="strand")
            spec.attach(child, frame=head.add_frame(), prefix=f"h{k}_")
        # MuJoCo's arena guess for this model grows as nv^2 (25 GB at 300 strands: the
        # allocation fails); the budget derods gives its own large worlds, doubled for the
        # flex solver's M + K.
        n = case.strands * case.vertices
        spec.memory = 2 * layout.arena_budget(4 * n, 2 * n + case.strands + 64)
        t0 = time.perf_counter()
        self.model = spec.compile()
        self.mujoco_compile_s = time.perf_counter() - t0
        m = self.model
        for b in range(m.nbody):
            if m.body_dofnum[b] == 3 and m.jnt_type[m.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_SLIDE:
                m.dof_damping[m.body_dofadr[b]:m.body_dofadr[b] + 3] = hair_mod.MASS_DAMPING * m.body_mass[b]
        self.data = mujoco.MjData(m)
        mujoco.mj_forward(m, self.data)
        self.motion = hair_mod.Motion(case.motion)
        body = m.body(hair_mod.HEAD).id
        self.mocap = int(m.body_mocapid[body])
        self.centre = m.body_pos[body].copy()
        self.pivot = m.site(hair_mod.NECK).pos.copy()
        self._steps = native.CheckedSteps(m, self.data, np.arange(m.nv), "native flex hair")
        self.shape = (case.strands, case.vertices)

    def step(self):
        d = self.data
        d.mocap_pos[self.mocap], d.mocap_quat[self.mocap] = self.motion.pose(d.time + self.model.opt.timestep,
                                                                             self.centre, self.pivot)
        self._steps.step()

    def positions(self) -> np.ndarray:
        return self.data.flexvert_xpos.reshape(self.shape[0], self.shape[1], 3).copy()


def run(case: HairCase, progress=None) -> dict:
    """Build and run ``case``; returns its record. progress: optional ``f(text)``."""
    h = case.hair
    t0 = time.perf_counter()
    sim = (_DerHair if case.backend == "der" else _FlexHair)(case)
    build_s = time.perf_counter() - t0
    if progress:
        progress(f"built {case.strands} strands ({case.backend}) in {build_s:.1f} s")
    rest = case.hair.segment
    n_steps = int(round(case.seconds / case.dt))
    late_from = hair_mod.Motion(case.motion).settle + TRANSIENT
    times, pen_late, pen_max, strain = [], 0.0, 0.0, 0.0
    stable, note, budget = True, "", ""
    try:
        for k in range(n_steps):
            budget = over_budget(k, n_steps, case.dt, sum(times), case.max_wall_s)
            if budget:
                break
            a = time.perf_counter()
            sim.step()
            times.append(time.perf_counter() - a)
            x = sim.positions()
            if not np.all(np.isfinite(x)):
                raise DivergenceError(f"positions not finite at step {k + 1}")
            c, _, skull = hair_mod.skull_pose(sim.model, sim.data)
            pen = hair_mod.sphere_penetration(x, c, skull, h.radius)
            pen_max = max(pen_max, pen)
            if (k + 1) * case.dt >= late_from:
                pen_late = max(pen_late, pen)
            strain = max(strain, hair_mod.edge_strain(x, rest))
    except DivergenceError as err:
        stable, note = False, str(err)
    drift = None
    if stable:
        drift = hair_mod.root_offset(sim.positions()[:, 0], h, *hair_mod.skull_pose(sim.model, sim.data))
    mat = h.material
    wall = float(np.sum(times))
    inertia = int(sim.data.warning[mujoco.mjtWarning.mjWARN_INERTIA].number)
    return {
        "case": "hair", "backend": case.backend, "mujoco_version": mujoco.__version__,
        "strands": case.strands, "vertices": case.vertices, "n_edges": case.vertices - 1, "dt": case.dt,
        "mode": "implicit" if case.backend == "der" else "native", "motion": case.motion,
        "strand_contact": case.strand_contact,
        "young": mat.young, "length": h.length, "radius": mat.radius, "density": mat.density,
        "build_s": build_s, "mujoco_compile_s": sim.mujoco_compile_s, "steps": len(times), "sim_s": len(times) * case.dt, "wall_s": wall,
        "us_per_step": 1e6 * wall / len(times) if times else None,
        "median_us_per_step": 1e6 * float(np.median(times)) if times else None,
        "stable": stable, "penetration": pen_late, "penetration_max": pen_max, "max_strain": strain,
        "root_drift": drift, "inertia_warnings": inertia,
        "note": note or "; ".join(t for t in (budget, NOTES[case.backend], (
            f"MuJoCo reported a singular inertia (its M + K solve not converged) {inertia} times" if inertia
            else "")) if t),
    }


def format_record(rec: dict) -> str:
    """One readable line for a hair record."""
    head = (f"hair {rec['backend']}: {rec['strands']} strands x {rec['vertices']} vertices, {rec['motion']}"
            f"{', strand contact' if rec.get('strand_contact') else ''}, "
            f"dt={rec['dt']:g} | build {rec['build_s']:.2f} s")
    if not rec["stable"]:
        return f"{head} | UNSTABLE: {rec['note']}"
    return (f"{head} | {rec['us_per_step'] / 1e3:.1f} ms/step (median {rec['median_us_per_step'] / 1e3:.1f}) | "
            f"penetration {rec['penetration'] * 1e3:.3f} mm after impacts ({rec['penetration_max'] * 1e3:.3f} "
            f"max) | strain {rec['max_strain']:.1e} | root drift {rec['root_drift']:.1e} m")


def main(case: HairCase, as_json: bool, stream=None) -> int:
    """Run the hair case and print its record; returns a process exit code."""
    stream = sys.stdout if stream is None else stream
    rec = run(case, progress=None if as_json else (lambda text: print(text, file=sys.stderr, flush=True)))
    print(json.dumps(rec) if as_json else format_record(rec), file=stream, flush=True)
    return 0
