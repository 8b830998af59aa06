"""Divergence: how a step that lost the solution is recognised and reported.

Shared by derods' :class:`~derods.sim.world.World` and MuJoCo's native rods in the
comparison harness, so that every backend fails by the same rules: an edge
stretched beyond :data:`MAX_STRAIN`, a vertex faster than :data:`MAX_SPEED` or
not finite, or MuJoCo's bad-acceleration reset (``mjWARN_BADQACC``). The error
names the step, the rod and a fix.
"""

from __future__ import annotations

import mujoco
import numpy as np

#: Divergence thresholds: an edge stretched beyond this strain, or a vertex faster
#: than this [m/s], means the step has lost the solution.
MAX_STRAIN = 0.5
MAX_SPEED = 1e3


class DivergenceError(RuntimeError):
    """The simulation lost the solution; the message names the step, the rod and a fix."""


class Diagnosis:
    """Raises :class:`DivergenceError` with the step, the rod and what to change.

    names: rod names, by index. dt [s], mode, mass_damping [1/s]: what the hint suggests
    changing (None for a backend without these knobs).
    """

    def __init__(self, names, dt: float | None = None, mode: str | None = None,
                 mass_damping: float | None = None):
        self.names = list(names)
        self.dt, self.mode, self.mass_damping = dt, mode, mass_damping

    def _fail(self, rod: int | None, what: str, step: int, time: float):
        if rod is None:
            who = f"rod '{self.names[0]}'" if len(self.names) == 1 else "a rod"
        else:
            who = f"rod '{self.names[rod]}'"
        hint = ""
        if self.dt is not None:
            hint = (f"; try a smaller dt (now {self.dt:g} s)"
                    + ("" if self.mode in (None, "implicit") else ", mode='implicit'")
                    + (f", or more damping (mass_damping now {self.mass_damping:g} 1/s)"
                       if self.mass_damping is not None else ""))
        raise DivergenceError(f"{who} diverged at step {step} (t = {time:.6g} s): {what}{hint}")

    def strain(self, rod: int, strain: float, step: int, time: float):
        self._fail(rod, f"edge strain {strain:.3g} exceeds {MAX_STRAIN:g}", step, time)

    def projection(self, rod: int, max_iter: int, step: int, time: float):
        self._fail(rod, f"projecting its edges back to their rest lengths did not converge in {max_iter} "
                        "iterations", step, time)

    def badqacc(self, step: int, time: float):
        self._fail(None, "MuJoCo reported bad accelerations (BADQACC) and reset the state", step, time)

    def not_positive_definite(self, what: str, step: int, time: float):
        self._fail(None, f"the implicit system is not positive definite ({what}): the rods' stiffness is out of "
                         "proportion to their masses (check young, radius, density)", step, time)

    def speed(self, rod: int, velocity: float, step: int, time: float):
        if not np.isfinite(velocity):
            self._fail(rod, "NaN or infinite state", step, time)
        self._fail(rod, f"vertex speed {abs(velocity):.3g} m/s exceeds {MAX_SPEED:g}", step, time)


def check_mujoco(data: mujoco.MjData, dofs: np.ndarray, badqacc_seen: int, diagnosis: Diagnosis,
                 step: int) -> int:
    """Raise if MuJoCo reset the state or a dof in ``dofs`` is not finite or too fast; returns
    the BADQACC count to compare against next time (a backend that is plain MuJoCo)."""
    n_bad = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
    if n_bad != badqacc_seen:
        diagnosis.badqacc(step, data.time)
    v = data.qvel[dofs]
    if len(v) and not np.max(np.abs(v)) <= MAX_SPEED:
        k = int(np.flatnonzero(~np.isfinite(v))[0]) if not np.all(np.isfinite(v)) else int(np.argmax(np.abs(v)))
        diagnosis.speed(0, float(v[k]), step, data.time)
    return n_bad
