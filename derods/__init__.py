"""derods: Discrete Elastic Rods (Bergou et al. 2008) on MuJoCo.

The core is pure numpy/scipy: :mod:`derods.geometry` (edges, curvature
binormal, vertex lengths), :mod:`derods.frames` (Bishop, reference and
material frames), :mod:`derods.energy` (stretch, bend and twist energies with
exact gradients and Hessians), :mod:`derods.twist` (the quasistatic material
frame), :mod:`derods.shapes` (rest shapes and Bezier curves) and
:mod:`derods.rod` (parameters, state and the active energy terms).
"""

from .energy import Configuration, Derivatives
from .rod import Material, Rod, RodState
from .stencil import Hessian
from .twist import TwistBoundary
from . import frames, geometry, shapes

__version__ = "0.1.0"

__all__ = [
    "Configuration",
    "Derivatives",
    "Hessian",
    "Material",
    "Rod",
    "RodState",
    "TwistBoundary",
    "frames",
    "geometry",
    "shapes",
    "__version__",
]
