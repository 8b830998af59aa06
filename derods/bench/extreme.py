"""Benchmark case ``extreme``: rods far outside the comfortable range, judged by what
happened to them (stable, diverged, penetrated) rather than by an error."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from .. import shapes
from ..sim.divergence import DivergenceError
from . import native
from .measures import StepClock, closest_approach, record
from .params import BACKEND_CASES, CaseParams


def extreme(p: CaseParams) -> list[dict]:
    """Extreme cases; measured: what happened ("stable", "diverged", "penetrated").

    soft: E = 1e4 Pa cantilever; steel wire: E = 2e11 Pa, r = 0.5 mm cantilever;
    impact: a free rod thrown at the floor at 20 m/s; hairpin: a rod folded back on
    itself (bend radius 2 r) released; edge ratio: a cantilever whose second edge is
    1000 times shorter than the others; ring 20 turns: a ring twisted 20 full turns
    (far above Michell's threshold), which writhes; derods has self-contact on, the
    native rings have none (see :mod:`derods.bench.backends`): "penetrated" if two
    non-neighbouring parts of the rod come closer than r.
    """
    out = []
    if p.backend == "cable":
        # A composite cable takes uniform segments and sets shapes only when clamped: no
        # hairpin, no 1000:1 edges.
        variants = ["soft", "steel_wire", "impact", "ring_20_turns"]
    else:
        variants = ["soft", "steel_wire", "impact", "hairpin", "edge_ratio"] + (
            ["ring_20_turns"] if "michell" in BACKEND_CASES[p.backend] else [])
    for name in variants:
        q = p
        t0 = time.perf_counter()
        watching = 0.0  # time spent checking the run, not running it [s]
        world, outcome, note = None, "stable", ""
        try:
            if name in ("soft", "steel_wire"):
                q = dataclasses.replace(p, young=1e4) if name == "soft" else dataclasses.replace(
                    p, young=2e11, radius=5e-4, density=7850.0)
                world = StepClock(q.build.cantilever(q, q.gravity, 1.0)[0])
                world.step(int(round(2.0 / q.dt)))
            elif name == "impact":
                x = shapes.straight(q.length, q.n_edges, start=(-0.5 * q.length, 0.0, 0.3),
                                    direction=(1.0, 0.0, 0.3))
                world = StepClock(q.build.free_rod(q, x, "floor"))
                world.set_velocities(0, np.tile([0.0, 0.0, -20.0], (len(x), 1)))
                deepest = 0.0
                for _ in range(int(round(0.5 / q.dt))):
                    world.step()
                    deepest = max(deepest, q.radius - float(world.positions()[:, 2].min()))
                if world.positions()[:, 2].min() < -q.radius:
                    outcome = "penetrated"  # it went through the floor and stayed there
                note = f"deepest penetration during impact {1000 * deepest:.1f} mm (r = {1000 * q.radius:g} mm)"
            elif name == "hairpin":
                k = q.n_edges // 2
                s = np.linspace(0, q.length, q.n_edges + 1)
                bend = 2 * q.radius
                x = np.stack([np.where(s < q.length / 2, s, q.length - s), np.zeros_like(s),
                              np.where(s < q.length / 2, 0.0, 2 * bend)], axis=1) + (0.0, 0.0, 0.5)
                x[k] += (0.0, 0.0, bend)
                world = StepClock(q.build.free_rod(q, x, None))
                world.step(int(round(1.0 / q.dt)))
            elif name == "edge_ratio":
                x = shapes.straight(q.length, q.n_edges, start=(0.0, 0.0, 1.0))
                x[2] = x[1] + (x[2] - x[1]) * 1e-3
                world = StepClock(q.build.clamped_rod(q, x, q.gravity, 0.0))
                world.step(int(round(1.0 / q.dt)))
            else:  # ring_20_turns
                world = StepClock(q.build.twisted_ring(q, 40 * math.pi, self_contact=True))
                xp = native.ring_vertices(q)
                xp[:, 2] += 1e-3 * np.sin(2 * np.linspace(0, 2 * math.pi, q.n_edges, endpoint=False))
                world.set_positions(0, xp)
                gap = math.inf
                for _ in range(int(round(1.0 / q.dt)) // 5):  # watch for the ring passing through itself
                    world.step(5)
                    t_watch = time.perf_counter()
                    gap = min(gap, closest_approach(world.positions(), q.length / q.n_edges))
                    watching += time.perf_counter() - t_watch
                note = (f"closest approach of non-neighbouring parts {1000 * gap:.1f} mm "
                        f"(r = {1000 * q.radius:g} mm)")
                if gap < q.radius:
                    outcome = "penetrated"
            if not np.all(np.isfinite(world.positions())):
                outcome = "NaN"
        except DivergenceError as err:
            outcome, note = "diverged", str(err)
        except Exception as err:  # a setup the backend refuses is an outcome too
            outcome, note = "failed", f"{type(err).__name__}: {err}"
        wall = time.perf_counter() - t0 - watching
        rec = record("extreme", q, world, None, None, outcome == "stable", wall, variant=name,
                     outcome=outcome, note=note)
        out.append(rec)
    return out
