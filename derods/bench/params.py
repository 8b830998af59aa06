"""What a benchmark case runs: the rod and time stepping (:class:`CaseParams`), the derods
modes, and which backend runs which case."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..material import Material
from ..sim.world import MODES as _WORLD_MODES
from . import native
from .backends import BACKENDS as _BACKENDS

#: The derods modes a case can run in (a World's, without "auto").
DER_MODES = tuple(m for m in _WORLD_MODES if m != "auto")
CASES = ("cantilever", "frequency", "drop", "michell", "circle", "twist", "stability", "extreme", "oscillation",
         "coupling")
BACKENDS = tuple(_BACKENDS)
#: Cases each backend can run.
BACKEND_CASES = {"der": ("cantilever", "frequency", "drop", "michell", "circle", "twist", "stability",
                         "extreme", "oscillation", "coupling"),
                 "flex": ("cantilever", "frequency", "drop", "circle", "stability", "extreme", "oscillation")
                 + (("michell",) if native.has_flex_twist() else ()),
                 "cable": ("cantilever", "frequency", "michell", "circle", "drop", "stability", "extreme",
                           "oscillation"),
                 "elastica": ("cantilever", "frequency", "oscillation")}


@dataclass(frozen=True)
class CaseParams:
    """The rod and the time stepping shared by every case (SI units).

    n_edges: edges of the rod. dt: time step [s]. young: E [Pa]. shear: G [Pa]
    (None: from poisson). length [m], radius [m], density [kg/m^3], gravity
    [m/s^2] (magnitude, pointing down). mode: one of DER_MODES.
    backend: "der", MuJoCo's native "flex" or "cable", or "elastica" (PyElastica, at the dt
    given: :func:`derods.bench.elastica.search_dt` finds its largest stable one)
    (:mod:`derods.bench.backends`).
    """

    n_edges: int = 20
    dt: float = 1e-2
    young: float = 1e8
    shear: float | None = None
    poisson: float = 0.5
    length: float = 1.0
    radius: float = 0.01
    density: float = 1000.0
    gravity: float = 9.81
    mode: str = "implicit"
    backend: str = "der"

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        missing = _BACKENDS[self.backend].requirement()
        if missing:
            raise ValueError(missing)
        if self.mode not in DER_MODES:
            raise ValueError(f"mode must be one of {DER_MODES}, got {self.mode!r}")
        if int(self.n_edges) != self.n_edges or self.n_edges < 2:
            raise ValueError(f"n_edges must be an integer >= 2, got {self.n_edges!r}")
        for name, unit in (("dt", "s"), ("length", "m")):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be finite and > 0 [{unit}], got {getattr(self, name)!r}")
        if self.gravity < 0:
            raise ValueError(f"gravity is a magnitude and must be >= 0 [m/s^2], got {self.gravity!r}")

    @property
    def material(self) -> Material:
        return Material(young=self.young, density=self.density, radius=self.radius,
                        shear=self.shear, poisson=self.poisson)

    @property
    def build(self):
        """How this run's backend builds its rods (:class:`derods.bench.backends.Backend`)."""
        return _BACKENDS[self.backend]
