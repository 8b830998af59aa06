"""Per-step cost of derods in MuJoCo against MuJoCo's native 1D flexcomp, same run.

The same horizontal cantilever (L = 1 m, r = 1 cm, rho = 1000 kg/m^3, E = 1e8 Pa,
clamped, under gravity) at the same n and dt = 1e-2, two ways:

* derods: ``derods.World``, implicit DER step (stretch + bending), MuJoCo for
  integration;
* native: MuJoCo's 1D flexcomp with ``<elasticity young>`` (its own DER),
  ``pin 0 1`` clamp, edge equality (solref 1e-4), ``discrete`` integrator:
  the setting the native baselines found stable at dt = 1e-2.

Each is warmed up for 200 steps, then 2000 steps are timed one by one; the
median is reported, and the best median of --repeat interleaved runs (the VM's
speed drifts, so compare within a row). A second table shows what pruning
saves: the same rod with work it does not need (twist solve forced on by
clamping both ends; contacts against a distant floor forced on) against the
world that skips it.

Run: .venv/bin/python benchmarks/bench_world.py [--repeat 3] [--steps 2000]
Targets (MuJoCo coupling issue): derods/native <= 0.6 at n = 200, <= 2 at n = 20.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

import derods
from derods import shapes
from derods import World

E, R, RHO, L, DT = 1e8, 0.01, 1000.0, 1.0, 1e-2


def native_step(n: int):
    pts = " ".join(f"{i * L / n:.9g} 0 1" for i in range(n + 1))
    elem = " ".join(f"{i} {i + 1}" for i in range(n))
    xml = f"""<mujoco><option timestep="{DT}" integrator="discrete"/><worldbody>
      <flexcomp name="rod" type="direct" dim="1" point="{pts}" element="{elem}" radius="{R}"
                mass="{RHO * np.pi * R * R * L}">
        <pin id="0 1"/><edge equality="true" solref="0.0001 1"/><contact selfcollide="none"/>
        <elasticity young="{E}" poisson="0.49" damping="0"/>
      </flexcomp></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    return lambda: mujoco.mj_step(m, d)


def derods_step(n: int, end: str = "free", floor: bool = False):
    scene = None
    if floor:
        scene = mujoco.MjSpec()
        g = scene.worldbody.add_geom()
        g.type = mujoco.mjtGeom.mjGEOM_PLANE
        g.size = [5, 5, 0.1]
        g.pos = [0, 0, -10]  # far below: contacts are checked, none are found
    w = World(scene, dt=DT, mass_damping=6.0, integrator="implicitfast")
    rod = derods.Rod(shapes.cantilever(L, n, start=(0, 0, 1)), derods.Material(young=E, radius=R, density=RHO))
    if end == "clamp":
        rod = rod.with_boundary(derods.TwistBoundary("clamped", 0.0, 0.0))
    w.add_rod(rod, start="clamp", end=end)
    w.compile()
    return lambda: w.step()


def median_us(step, steps: int) -> float:
    for _ in range(200):
        step()
    t = np.empty(steps)
    for k in range(steps):
        t0 = time.perf_counter()
        step()
        t[k] = time.perf_counter() - t0
    return float(np.median(t)) * 1e6


def main(argv=None):
    ap = argparse.ArgumentParser(description="derods vs native MuJoCo flexcomp, per-step cost")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--steps", type=int, default=2000)
    args = ap.parse_args(argv)
    print(f"mujoco {mujoco.__version__}, derods {derods.__version__}; cantilever E = {E:g} Pa, dt = {DT:g} s")
    print(f"{'n':>5} {'derods us':>10} {'native us':>10} {'ratio':>7}  target")
    for n in (20, 50, 200):
        ours, native = [], []
        for _ in range(args.repeat):
            ours.append(median_us(derods_step(n), args.steps))
            native.append(median_us(native_step(n), args.steps))
        a, b = min(ours), min(native)
        target = {20: "<= 2", 200: "<= 0.6"}.get(n, "")
        print(f"{n:>5} {a:10.1f} {b:10.1f} {a / b:7.2f}  {target}")
    print("\nwhat pruning saves (n = 200, median us per step)")
    base = min(median_us(derods_step(200), args.steps) for _ in range(args.repeat))
    tw = min(median_us(derods_step(200, end="clamp"), args.steps) for _ in range(args.repeat))
    fl = min(median_us(derods_step(200, floor=True), args.steps) for _ in range(args.repeat))
    print(f"  free end (no twist term), no obstacles: {base:8.1f}")
    print(f"  both ends clamped (twist term + solve): {tw:8.1f}  (+{tw - base:.1f})")
    print(f"  a floor to check contacts against:      {fl:8.1f}  (+{fl - base:.1f})")


if __name__ == "__main__":
    main()
