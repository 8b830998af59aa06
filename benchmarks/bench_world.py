"""Per-step cost of derods in MuJoCo against MuJoCo's native 1D flexcomp, same run.

Each case is built twice from the same description, as derods ``World`` (implicit
DER step, MuJoCo for contact and integration) and as native flexcomps
(``<elasticity young>``, pinned first edge for a clamp, edge equality solref 1e-4,
``discrete`` integrator: the setting the native baselines found stable at dt = 1e-2;
see :mod:`derods.bench.native`). Runs alternate derods / native / derods ...,
``--repeat`` times; each run gives the median of its timed steps, and a case
reports the median over its runs. The VM's speed drifts: the ratio derods /
native within a row is the figure to read, not the microseconds.

Cases:

* cantilever n = 20, 50, 200, 1000: L = 1 m, r = 1 cm, rho = 1000 kg/m^3,
  E = 1e8 Pa, clamped, under gravity, dt = 1e-2 s (mass damping 6 / s).
* drop n = 50 on the box edge and on the floor: the ``drop`` case's rod (E = 1e7 Pa,
  dropped from 0.5 m, mass damping 2 / s), dt = 1e-2 s; every step of 3 s timed
  (falling, impact, lying).
* demo: the main job's world (``derods drop`` defaults: 3 rods x 40 edges dropped
  on each other onto the box, dt = 2e-3 s), every step of 4 s timed.
* R = 1, 10, 100 rods of 32 vertices (h = 1 cm, r = 2 mm, E = 1e8 Pa, dt = 1e-2 s),
  hanging from a clamp and lying on the floor; then the marginal cost of one more
  rod, (t(100) - t(10)) / 90, and the build times.
* held (derods only): the held-rods sweep's cable lying on a floor (0.5 m, 32 edges,
  r = 3 mm, E = 1e7 Pa, dt = 5e-3 s, derods.bench.held "drag" at rest), its start pinned or
  clamped to a 1 kg cart on a servo-driven slide (the coupled solve of rods, holder and
  contacts) against the same cable held by a mocap cart; target: ratio <= 1.5.
* pruning (derods only): the n = 200 cantilever with a free end and no obstacle,
  against the same with both ends clamped (twist term and solve) and with a floor
  far below (collision checks that find nothing).

Run: .venv/bin/python benchmarks/bench_world.py [--repeat 3] [--quick] [--json FILE]
Targets (issue "one compiled step"): ratio <= 1.0 at n = 20 and <= 0.45 at n = 200,
<= 0.8 on the box edge and <= 1.0 on the floor; <= 40 us per extra hanging rod.
"""

from __future__ import annotations

import argparse
import json
import time

import mujoco
import numpy as np

import derods
from derods import World, scenes, shapes
from derods.apps.drop import DropParams, build_world
from derods.bench import CaseParams, native
from derods.bench.backends import BACKENDS


class MuJoCoModel:
    """A bare MuJoCo model and data with a step(); how the native side is timed."""

    def __init__(self, model, data):
        self.model, self.data = model, data

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            mujoco.mj_step(self.model, self.data)


def median_us(sim, steps: int, warm: int) -> float:
    sim.step(warm)
    t = np.empty(steps)
    for k in range(steps):
        t0 = time.perf_counter()
        sim.step()
        t[k] = time.perf_counter() - t0
    return float(np.median(t)) * 1e6


# --- the cases: (derods builder, native builder, steps timed, warm-up steps) ---------------------

def cantilever(n: int):
    def build(backend):
        p = CaseParams(n_edges=n, young=1e8, backend=backend)
        sim, _ = BACKENDS[backend].cantilever(p, p.gravity, 6.0)
        return sim
    steps = 200 if n >= 1000 else 500
    return lambda: build("der"), lambda: build("flex"), steps, 100


def drop(scene: str):
    def build(backend):
        p = CaseParams(n_edges=50, young=1e7, backend=backend)
        x = shapes.straight(p.length, p.n_edges)
        x -= x.mean(axis=0)
        x += (0.15, 0.0, 0.7) if scene == "box" else (0.0, 0.0, 0.5)
        return BACKENDS[backend].free_rod(p, x, scene, 2.0)
    return lambda: build("der"), lambda: build("flex"), 300, 0


def demo():
    params = DropParams()

    def native_demo():
        world = build_world(params)  # the same placement, read back from derods' world
        rods = [world.positions(i) for i in range(params.rods)]
        mat = params.material
        p = CaseParams(n_edges=params.n_edges, dt=params.dt, young=mat.young, radius=mat.radius,
                       density=mat.density, length=params.length, backend="flex")
        return MuJoCoModel(*native.flex_world(rods, p, scene=params.scene, mass_damping=params.mass_damping))

    steps = int(round(params.seconds / params.dt))
    return lambda: build_world(params), native_demo, steps, 0


STRAND = dict(n_edges=31, length=0.31, radius=0.002, young=1e8)


def strands(count: int, lying: bool):
    """count rods of 32 vertices, 2 cm apart: hanging from a clamp (straight down from
    z = 1 m), or lying on the floor along x."""
    def rest(i):
        if lying:
            return shapes.straight(STRAND["length"], STRAND["n_edges"], start=(0.0, 0.02 * i, STRAND["radius"]))
        return shapes.cantilever(STRAND["length"], STRAND["n_edges"], start=(0.02 * i, 0.0, 1.0),
                                 direction=(0.0, 0.0, -1.0))

    def der():
        p = CaseParams(**STRAND)
        world = World(scenes.path("floor") if lying else None, dt=p.dt, mass_damping=2.0,
                      gravity=(0.0, 0.0, -p.gravity))
        for i in range(count):
            world.add_rod(derods.Rod(rest(i), p.material, natural_curvature=not lying), f"s{i}",
                          start="free" if lying else "clamp")
        world.compile()
        return world

    def flex():
        p = CaseParams(**STRAND, backend="flex")
        rods = [rest(i) for i in range(count)]
        if not lying:  # the native clamp pins the first edge of a rod starting at the clamp
            rods = [shapes.straight(p.length, p.n_edges, start=(0.02 * i, 0.0, 1.0), direction=(0.0, 0.0, -1.0))
                    for i in range(count)]
        return MuJoCoModel(*native.flex_world(rods, p, pinned=() if lying else (0, 1),
                                              scene="floor" if lying else None, mass_damping=2.0))

    return der, flex, 60 if count >= 100 else 150, 20


def pruned(n: int, end: str = "free", floor: bool = False):
    """The cantilever (derods only) with work it does not need forced on: both ends clamped
    (the twist term and its solve), or a floor far below (collision checks, no contact)."""
    scene = None
    if floor:
        scene = mujoco.MjSpec()
        scene.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        scene.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1], pos=[0, 0, -10])
    world = World(scene, dt=1e-2, mass_damping=6.0)
    rod = derods.Rod(shapes.cantilever(1.0, n, start=(0, 0, 1)), derods.Material(young=1e8))
    if end == "clamp":
        rod = rod.with_boundary(derods.TwistBoundary("clamped", 0.0, 0.0))
    world.add_rod(rod, start="clamp", end=end)
    world.compile()
    return world


def run_pruning(repeat: int, out: dict) -> None:
    """What skipping unneeded work saves at n = 200, interleaved runs of the three worlds."""
    runs = {"free end, no obstacle": [], "both ends clamped (twist)": [], "a floor 10 m below": []}
    builders = [lambda: pruned(200), lambda: pruned(200, end="clamp"), lambda: pruned(200, floor=True)]
    for _ in range(repeat):
        for (label, sink), build in zip(runs.items(), builders):
            sink.append(median_us(build(), 500, 100))
    base = float(np.median(runs["free end, no obstacle"]))
    print("\nwhat skipping unneeded work saves (derods, cantilever n = 200, median us per step)")
    for label, sink in runs.items():
        t = float(np.median(sink))
        out[f"pruning: {label}"] = {"derods_us": t}
        print(f"  {label:28s} {t:8.0f}  ({t - base:+.0f})")


def run_held(repeat: int, out: dict) -> None:
    """A cable lying on a floor held by a cart with dofs against the same held by a mocap
    cart, interleaved runs, median us per step."""
    from derods.bench import held

    print("\nheld by a body with dofs (1 kg slide cart) vs by a mocap cart, cable lying on a floor")
    for end in ("pin", "clamp"):
        runs = {"slide": [], "mocap": []}
        for r in range(repeat):
            for holder in (("slide", "mocap") if r % 2 == 0 else ("mocap", "slide")):
                world = held.build(held.Case("drag", holder, mass=1.0, end=end, dt=5e-3)).world
                runs[holder].append(median_us(world, 300, 50))
        a, b = float(np.median(runs["slide"])), float(np.median(runs["mocap"]))
        out[f"held {end}: slide cart vs mocap"] = {"slide_us": a, "mocap_us": b, "ratio": a / b}
        print(f"  {end:6s} slide {a:8.0f}  mocap {b:8.0f}  ratio {a / b:5.2f}", flush=True)


def run_case(name, case, repeat: int, out: dict) -> None:
    der_build, flex_build, steps, warm = case
    ours, theirs, builds = [], [], {"der": [], "flex": []}
    for r in range(repeat):
        order = (("der", der_build, ours), ("flex", flex_build, theirs))
        for label, build, sink in (order if r % 2 == 0 else order[::-1]):
            t0 = time.perf_counter()
            sim = build()
            builds[label].append(time.perf_counter() - t0)
            sink.append(median_us(sim, steps, warm))
    a, b = float(np.median(ours)), float(np.median(theirs))
    out[name] = {"derods_us": a, "flex_us": b, "ratio": a / b, "runs_derods": ours, "runs_flex": theirs,
                 "build_s_derods": float(np.median(builds["der"])), "build_s_flex": float(np.median(builds["flex"]))}
    spread = f"{min(ours):.0f}-{max(ours):.0f} / {min(theirs):.0f}-{max(theirs):.0f}"
    print(f"{name:28s} {a:10.0f} {b:10.0f} {a / b:7.2f}   ({spread})", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description="derods vs MuJoCo's native flexcomp, per-step cost, same run")
    ap.add_argument("--repeat", type=int, default=3, help="runs per case and backend (default 3)")
    ap.add_argument("--quick", action="store_true", help="skip n = 1000, the demo and R = 100")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    print(f"mujoco {mujoco.__version__}, derods {derods.__version__}; median us per step over "
          f"{args.repeat} interleaved runs each (min-max of the runs in brackets)")
    print(f"{'case':28s} {'derods us':>10s} {'native us':>10s} {'ratio':>7s}")
    out = {}
    cases = [(f"cantilever n = {n}", cantilever(n)) for n in ((20, 50, 200) if args.quick else (20, 50, 200, 1000))]
    cases += [("drop n = 50, box edge", drop("box")), ("drop n = 50, floor", drop("floor"))]
    if not args.quick:
        cases.append(("demo: 3 rods x 40 on the box", demo()))
    counts = (1, 10) if args.quick else (1, 10, 100)
    for lying in (False, True):
        for count in counts:
            cases.append((f"R = {count} {'lying' if lying else 'hanging'} x 32", strands(count, lying)))
    for name, case in cases:
        run_case(name, case, args.repeat, out)
    if not args.quick:
        print("\nmarginal cost of one more rod of 32 vertices, (t(100) - t(10)) / 90 [us]:")
        for kind in ("hanging", "lying"):
            t10, t100 = out[f"R = 10 {kind} x 32"], out[f"R = 100 {kind} x 32"]
            d = (t100["derods_us"] - t10["derods_us"]) / 90
            f = (t100["flex_us"] - t10["flex_us"]) / 90
            out[f"marginal {kind}"] = {"derods_us": d, "flex_us": f}
            print(f"  {kind:8s} derods {d:8.1f}   native {f:8.1f}")
        print("\nbuild time [s] (median): " + "; ".join(
            f"{k}: {v['build_s_derods']:.2f} / {v['build_s_flex']:.2f}" for k, v in out.items()
            if k.startswith("R = ") and "build_s_derods" in v))
    run_held(args.repeat, out)
    if not args.quick:
        run_pruning(args.repeat, out)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
