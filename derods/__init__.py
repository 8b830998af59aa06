"""derods: Discrete Elastic Rods (Bergou et al. 2008) on MuJoCo.

The core is pure numpy/scipy: :mod:`derods.geometry` (edges, curvature
binormal, vertex lengths), :mod:`derods.frames` (Bishop, reference and
material frames), :mod:`derods.energy` (stretch, bend and twist energies with
exact gradients and Hessians), :mod:`derods.twist` (the quasistatic material
frame), :mod:`derods.shapes` (rest shapes and Bezier curves),
:mod:`derods.material` (the elastic constants), :mod:`derods.rod` (the frozen rod
and its active energy terms) and :mod:`derods.rod_state` (what changes). Rods in
MuJoCo: :class:`World` (:mod:`derods.sim`); scenes that ship with derods:
:mod:`derods.scenes`. Importing derods sets nothing up (no GL backend, no
environment variables); rendering chooses its backend when first used.
Inputs derods cannot simulate are refused at this boundary by :mod:`derods.validation`
with an :class:`InvalidInputError` (a ``ValueError``) or :class:`InvalidTypeError` (also
a ``TypeError``) that names the parameter, the value and what to pass.
"""

from typing import TYPE_CHECKING

from .energy import Configuration, Derivatives
from .material import Material
from .rod import Rod
from .rod_state import RodState
from .stencil import Hessian
from .twist import TwistBoundary
from .validation import InvalidIndexError, InvalidInputError, InvalidTypeError, SceneWarning
from . import frames, geometry, shapes

if TYPE_CHECKING:  # served lazily by __getattr__ below; named here for type checkers and the API reference
    from .sim.divergence import DivergenceError
    from .sim.world import MODES, ContactParams, World

__version__ = "0.1.0"

#: Names served from :mod:`derods.sim` on first use, so that ``import derods`` stays light
#: (the simulation layer loads MuJoCo and the compiled kernels).
_SIM_NAMES = {"World": "derods.sim.world", "ContactParams": "derods.sim.world",
              "DivergenceError": "derods.sim.divergence", "MODES": "derods.sim.world"}


def __getattr__(name):
    if name in _SIM_NAMES:
        import importlib

        return getattr(importlib.import_module(_SIM_NAMES[name]), name)
    raise AttributeError(f"module 'derods' has no attribute {name!r}")


__all__ = [
    "ContactParams",
    "Configuration",
    "DivergenceError",
    "MODES",
    "Derivatives",
    "Hessian",
    "InvalidIndexError",
    "InvalidInputError",
    "InvalidTypeError",
    "Material",
    "Rod",
    "RodState",
    "SceneWarning",
    "TwistBoundary",
    "World",
    "frames",
    "geometry",
    "shapes",
    "__version__",
]
