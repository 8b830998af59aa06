"""What a benchmark case measures, and its record.

A record (:func:`record`) is one dict per run with the same fields for every case: what
was run (case, backend, mujoco_version, n_edges, dt, mode, young, shear, length, radius,
density, gravity), what came out (measured, reference, rel_error, stable), what it cost
(steps, sim_s, wall_s, us_per_step) and what the world evaluated (active_terms); cases
add fields of their own.

What a run cost: ``wall_s`` [s] is the whole run, the case's own reading of the rod
between steps included; ``us_per_step`` [us] is the median over the run's steps of the
time of the step alone, taken by a :class:`StepClock` around the simulator. A median of
steps is not moved by the few slow ones: the first step that needs a kernel numba has
not loaded yet in this process (tens of ms), a pause of the machine. Repeated runs
(``derods bench --repeats``, :func:`derods.bench.command.timed_run`) take the median of
those medians.

The rest reads a run: a tip's height and a recording of it, the
frequency and the amplitudes of a swing, how far a ring left its plane, the largest edge
strain, the closest approach of a loop to itself, what a rod puts on its clamp.
"""

from __future__ import annotations

import math
import time

import mujoco
import numpy as np

from ..sim.divergence import DivergenceError
from .backends import RodSimulator
from .params import CaseParams


class StepClock:
    """A simulator whose steps are timed: ``step`` times each call of the wrapped
    simulator's, everything else is the simulator's own. ``samples``: where the times go, a
    list of (seconds per step, steps) per call; pass one list to several clocks to pool
    their steps (a bisection's trial worlds)."""

    def __init__(self, sim: RodSimulator, samples: list | None = None):
        self.sim = sim
        self.samples = [] if samples is None else samples

    def step(self, n_steps: int = 1) -> None:
        t0 = time.perf_counter()
        self.sim.step(n_steps)
        self.samples.append(((time.perf_counter() - t0) / n_steps, n_steps))

    def __getattr__(self, name):
        if name == "sim":  # not set yet (a copy being made): no recursion
            raise AttributeError(name)
        return getattr(self.sim, name)


def median_step_us(samples) -> float | None:
    """The median time of one step [us] over (seconds per step, steps) samples, a call of
    n steps counting as n steps of its mean; None without a step."""
    if not samples:
        return None
    per, n = np.array(samples, dtype=float).T
    return 1e6 * float(np.median(np.repeat(per, n.astype(int))))


def over_budget(done: int, n_steps: int, dt: float, spent_s: float, budget_s: float | None) -> str:
    """Why a run stops early: its steps have taken ``spent_s`` [s] of wall time, more than
    ``budget_s`` (None: no budget), after ``done`` of ``n_steps`` steps of ``dt`` [s]; ""
    while within it."""
    if budget_s is None or spent_s <= budget_s:
        return ""
    return (f"stopped after {done} of {n_steps} steps ({done * dt:g} s simulated): the steps had "
            f"taken {spent_s:.0f} s, over the {budget_s:g} s budget")


def record(case: str, p: CaseParams, world: RodSimulator | None, measured, ref, stable: bool,
           wall: float, **extra) -> dict:
    """The record of one run of ``case`` (fields: see the module docstring): ``measured``
    against ``ref``, ``wall`` [s] the run's wall time, ``extra`` the case's own fields.
    ``us_per_step``: the median step of ``world``'s StepClock (a bare simulator: wall / steps)."""
    steps = world.n_steps if world is not None else 0
    per_step = median_step_us(world.samples) if isinstance(world, StepClock) else (
        1e6 * wall / steps if steps else None)
    mat = p.material
    rel = (measured - ref) / ref if (measured is not None and ref) else None
    return {
        "case": case,
        "backend": p.backend,
        "mujoco_version": mujoco.__version__,
        "n_edges": p.n_edges,
        "dt": p.dt,
        "mode": p.build.mode(p),
        "young": p.young,
        "shear": mat.shear_modulus,
        "length": p.length,
        "radius": p.radius,
        "density": p.density,
        "gravity": p.gravity,
        "measured": measured,
        "reference": ref,
        "rel_error": rel,
        "stable": stable,
        "steps": steps,
        "sim_s": steps * p.dt,
        "wall_s": wall,
        "us_per_step": per_step,
        "active_terms": sorted({t for terms in world.active_terms.values() for t in terms}) if world else [],
        **extra,
    }


def clamp_reaction(world, stable: bool) -> dict:
    """What the rod puts on its clamp (derods' World.reaction: force [N] and moment [N m]
    about the clamp point, world frame), for the record; nothing for a backend without it."""
    if not stable or not hasattr(world, "reaction"):
        return {}
    force, moment = world.reaction(0, "start")
    return {"clamp_force": force.tolist(), "clamp_moment": moment.tolist()}


def tip_height(x: np.ndarray) -> float:
    """The last vertex's height above z = 1 m [m] of positions x (n_vertices, 3)."""
    return float(x[-1, 2] - 1.0)


def step_recording(world, n_steps: int, height) -> tuple[np.ndarray, bool, str, float]:
    """Step ``world`` n_steps times recording height(positions of its first rod) [m];
    returns (those heights (n_steps,), stable, the divergence's message or "", wall time
    [s]). After a divergence the heights past it are undefined."""
    z = np.empty(n_steps)
    t0 = time.perf_counter()
    stable, note = True, ""
    try:
        for k in range(n_steps):
            world.step()
            z[k] = height(world.positions())
    except DivergenceError as err:
        stable, note = False, str(err)
    return z, stable, note, time.perf_counter() - t0


def crossing_frequency(z: np.ndarray, dt: float) -> float | None:
    """The frequency [Hz] of a swing z (n,) sampled every dt [s] after each of n steps,
    from its upward zero crossings (linearly interpolated); None with fewer than two."""
    t = dt * np.arange(1, len(z) + 1)
    up = np.flatnonzero((z[:-1] < 0) & (z[1:] >= 0))
    crossings = t[up] - z[up] * dt / (z[up + 1] - z[up])
    if len(crossings) < 2:
        return None
    return float(1.0 / np.mean(np.diff(crossings)))


def swing_amplitudes(z: np.ndarray, hysteresis: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """The indices of the turning points of a sampled swing z (n,) and the peak-to-peak
    amplitude between each one and the next, shape (turns - 1,).

    A turning point counts once the swing has come back from it by ``hysteresis`` times
    the last swing (at first, z's whole range): ripples of faster modes riding on the
    swing (an explicit integrator keeps them all) are not turns, a decaying swing's
    late turns are. An extreme the record ends on, unconfirmed, is not counted."""
    z = np.asarray(z, dtype=float)
    if len(z) < 3:
        return np.zeros(0, dtype=int), np.zeros(0)
    band = hysteresis * float(np.ptp(z))
    turns, k, rising = [], 0, None
    for i in range(1, len(z)):
        if rising is None:
            if abs(z[i] - z[0]) > band:
                rising = z[i] > z[0]
                k = i
            continue
        if (z[i] > z[k]) == rising and z[i] != z[k]:
            k = i  # a new extreme in the current direction
        elif abs(z[i] - z[k]) > band:
            if turns:
                band = hysteresis * abs(z[k] - z[turns[-1]])
            turns.append(k)
            rising, k = not rising, i
    turns = np.array(turns, dtype=int)
    return turns, np.abs(np.diff(z[turns]))


def out_of_plane(x: np.ndarray) -> float:
    """Distance [m] of the vertices from their best-fit plane (rms)."""
    c = x - x.mean(axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / math.sqrt(len(x)))


def max_strain(x: np.ndarray, rest_x: np.ndarray) -> float:
    """The largest relative change of an edge's length, positions x (n, 3) [m] against
    rest_x (n, 3) [m] (open rods)."""
    le = np.linalg.norm(np.diff(x, axis=0), axis=1)
    return float(np.max(np.abs(le / np.linalg.norm(np.diff(rest_x, axis=0), axis=1) - 1)))


def closest_approach(x: np.ndarray, spacing: float, samples: int = 8) -> float:
    """Smallest distance [m] between points of a closed polyline ``x`` (n, 3) that lie
    more than 3 ``spacing`` apart along it. Each edge is sampled at ``samples`` points,
    so the answer exceeds the segment-to-segment distance by at most spacing / samples."""
    e = np.roll(x, -1, axis=0) - x
    s = (np.arange(samples) + 0.5) / samples
    pts = (x[:, None, :] + s[None, :, None] * e[:, None, :]).reshape(-1, 3)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(e, axis=1))])
    along = (arc[:-1, None] + s[None, :] * np.linalg.norm(e, axis=1)[:, None]).ravel()
    total = arc[-1]
    sep = np.abs(along[:, None] - along[None, :])
    sep = np.minimum(sep, total - sep)  # along a closed loop
    dist = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    return float(dist[sep > 3 * spacing].min())
