"""derods: Discrete Elastic Rods (Bergou et al. 2008) on MuJoCo.

The core is pure numpy/scipy: :mod:`derods.geometry` (edges, curvature
binormal, vertex lengths), :mod:`derods.frames` (Bishop, reference and
material frames), :mod:`derods.energy` (stretch, bend and twist energies with
exact gradients and Hessians), :mod:`derods.twist` (the quasistatic material
frame), :mod:`derods.shapes` (rest shapes and Bezier curves) and
:mod:`derods.rod` (parameters, state and the active energy terms).
"""

# MuJoCo picks its OpenGL backend when first imported: choose EGL (headless) first
# when there is no display, unless the user chose a backend.
from .render import ensure_headless_gl as _ensure_headless_gl

_ensure_headless_gl()

from .energy import Configuration, Derivatives  # noqa: E402
from .rod import Material, Rod, RodState  # noqa: E402
from .stencil import Hessian  # noqa: E402
from .twist import TwistBoundary  # noqa: E402
from . import frames, geometry, shapes  # noqa: E402

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
