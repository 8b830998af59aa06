"""Divergence: how a step that lost the solution is recognised and reported.

Shared by derods' :class:`~derods.sim.world.World` and MuJoCo's native rods in the
comparison harness, so that every backend fails by the same rules.
"""

from __future__ import annotations

#: Divergence thresholds: an edge stretched beyond this strain, or a vertex faster
#: than this [m/s], means the step has lost the solution.
MAX_STRAIN = 0.5
MAX_SPEED = 1e3


class DivergenceError(RuntimeError):
    """The simulation lost the solution; the message names the step, the rod and a fix."""
