"""PyElastica (Gazzola lab's Cosserat rods, explicit and symplectic) as a benchmark backend.

PyElastica lives in its own environment (``make venv-elastica`` creates
``.venv-elastica`` with pyelastica 1.0.0 beside derods), as the cable does in
MuJoCo 3.17's. It is set up as a careful PyElastica user would:

- the rod starts h/2 behind the clamp, as derods' (:func:`derods.shapes.cantilever`):
  ``OneEndFixedBC`` holds the first node and the first element's directors, so the
  clamp acts at the first element's middle (a rod that starts at the clamp ends 3-10 %
  off the elastica);
- the same material: E, G (derods' shear modulus), density, radius, and mass damping
  as ``AnalyticalLinearDamper``'s uniform rate [1/s] (exact, no dt limit of its own);
- PositionVerlet at the largest stable dt found by search
  (:func:`largest_stable_dt`), not at the dt a MuJoCo backend takes.

What it runs: cantilever, frequency, oscillation (clamped and free). Not: drop, stability, extreme
(MuJoCo's contacts and scenes; its own stability limit is what the dt search measures),
michell and twist (a ring with imposed total twist and an end twist need directors
set by hand that a comparison could get subtly wrong), circle (its end couple lives in
the material frame: expressible, left for later).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..sim.divergence import DivergenceError

#: A run's dt is this fraction of the largest stable dt the search finds: the search's
#: trials are short (TRIAL_TIME), the runs up to tens of seconds.
DT_MARGIN = 0.9
#: Simulated time [s] of one trial of the dt search.
TRIAL_TIME = 0.2


def available() -> str | None:
    """None if PyElastica imports here, else how to get it."""
    try:
        import elastica  # noqa: F401
    except ImportError:
        return ("backend 'elastica' needs PyElastica, which lives in its own environment: make venv-elastica, "
                "then run with .venv-elastica/bin/python")
    return None


class ElasticaRod:
    """One PyElastica Cosserat rod, clamped at its first element or free, behind the harness's
    protocol (:class:`derods.bench.backends.RodSimulator`; ``model`` and ``data`` are
    None: nothing here is MuJoCo's).

    x (n + 1, 3) [m]: straight rest vertices, first edge in the clamp. material: a
    :class:`derods.Material`. dt [s]; gravity [m/s^2] (magnitude, along -z); damping:
    uniform velocity damping rate [1/s] (0: none). clamped: hold the first node and the
    first element's directors (else the rod is free).
    """

    label = "PyElastica"
    active_terms = {"rod": ("bend", "twist", "stretch", "shear")}
    model = None
    data = None

    def __init__(self, x: np.ndarray, material, dt: float, gravity: float, damping: float = 0.0,
                 clamped: bool = True):
        import elastica as ea

        class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
            pass

        x = np.asarray(x, dtype=float)
        n = len(x) - 1
        axis = x[-1] - x[0]
        length = float(np.linalg.norm(axis))
        self.sim = Simulator()
        self.rod = ea.CosseratRod.straight_rod(
            n, start=x[0].copy(), direction=axis / length, normal=np.array([0.0, 0.0, 1.0]), base_length=length,
            base_radius=material.radius, density=material.density, youngs_modulus=material.young,
            shear_modulus=material.shear_modulus)
        self.sim.append(self.rod)
        self.clamped = clamped
        if clamped:
            self.sim.constrain(self.rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,),
                                               constrained_director_idx=(0,))
        if gravity:
            self.sim.add_forcing_to(self.rod).using(ea.GravityForces, acc_gravity=np.array([0.0, 0.0, -gravity]))
        if damping:
            self.sim.dampen(self.rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=damping,
                                            time_step=dt)
        self.sim.finalize()
        self.stepper = ea.PositionVerlet()
        self.dt = float(dt)
        self._time = 0.0
        self.n_steps = 0
        self.length = length

    @property
    def time(self) -> float:
        return self._time

    def step(self, n_steps: int = 1) -> None:
        for _ in range(n_steps):
            self._time = float(self.stepper.step(self.sim, self._time, self.dt))
            self.n_steps += 1
        tip = self.rod.position_collection[:, -1]
        if not np.all(np.isfinite(tip)) or np.linalg.norm(tip - self.rod.position_collection[:, 0]) > 2 * self.length:
            raise DivergenceError(f"PyElastica's rod diverged by step {self.n_steps} (t = {self._time:.4g} s) at "
                                  f"dt = {self.dt:g} s; its explicit step needs a smaller dt")

    def positions(self, rod=0) -> np.ndarray:
        return self.rod.position_collection.T.copy()

    def velocities(self, rod=0) -> np.ndarray:
        return self.rod.velocity_collection.T.copy()

    def set_positions(self, rod, x: np.ndarray) -> None:
        """Move the nodes to x (n + 1, 3) [m] at rest, turning each element's directors
        with its tangent (so that no shear is set), a clamped first element unchanged."""
        x = np.asarray(x, dtype=float)
        r = self.rod
        r.position_collection[:] = x.T
        r.velocity_collection[:] = 0.0
        r.omega_collection[:] = 0.0
        d = r.director_collection  # (3, 3, n): rows d1, d2, d3 of each element
        for k in range(1 if self.clamped else 0, d.shape[2]):
            t = x[k + 1] - x[k]
            t /= np.linalg.norm(t)
            d1 = d[0, :, k] - (d[0, :, k] @ t) * t
            d1 /= np.linalg.norm(d1)
            d[0, :, k], d[1, :, k], d[2, :, k] = d1, np.cross(t, d1), t

    def set_velocities(self, rod, v: np.ndarray) -> None:
        self.rod.velocity_collection[:] = np.asarray(v, dtype=float).T


def _stable(x: np.ndarray, material, dt: float, gravity: float) -> bool:
    """Whether the undamped cantilever at x stays finite, unstretched (edges within
    50 %) and within 1.5 L of its clamp for TRIAL_TIME under gravity."""
    rod = ElasticaRod(x, material, dt, gravity)
    rest = np.linalg.norm(np.diff(x, axis=0), axis=1)
    try:
        chunk = max(1, int(0.01 / dt))
        while rod.time < TRIAL_TIME:
            rod.step(chunk)
            y = rod.positions()
            strain = np.abs(np.linalg.norm(np.diff(y, axis=0), axis=1) / rest - 1.0)
            if not np.all(np.isfinite(y)) or strain.max() > 0.5 or np.linalg.norm(y[-1] - y[0]) > 1.5 * rod.length:
                return False
    except DivergenceError:
        return False
    return True


@functools.lru_cache(maxsize=None)
def largest_stable_dt(n_edges: int, young: float, shear: float, radius: float, density: float, length: float,
                      gravity: float) -> float:
    """The largest dt [s] at which PyElastica's undamped cantilever stays stable for
    TRIAL_TIME, to 2 significant digits (bisection in log dt from the explicit bound
    h / sqrt(E / rho)), times DT_MARGIN."""
    from ..material import Material
    from ..shapes import cantilever

    material = Material(young=young, shear=shear, radius=radius, density=density)
    x = cantilever(length, n_edges, start=(0.0, 0.0, 1.0))
    h = float(np.linalg.norm(x[1] - x[0]))
    lo = hi = h / math.sqrt(young / density)
    while not _stable(x, material, lo, gravity):
        lo /= 2
    while _stable(x, material, hi, gravity):
        lo, hi = hi, 2 * hi
    while hi / lo > 1.02:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if _stable(x, material, mid, gravity) else (lo, mid)
    digits = 10 ** math.floor(math.log10(lo) - 1)
    return float(math.floor(DT_MARGIN * lo / digits) * digits)


def search_dt(p) -> float:
    """:func:`largest_stable_dt` for a case's parameters (:class:`derods.bench.CaseParams`)."""
    mat = p.material
    return largest_stable_dt(p.n_edges, p.young, mat.shear_modulus, p.radius, p.density, p.length, p.gravity)
