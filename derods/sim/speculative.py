"""Speculative contacts sized by speed (``ContactParams(speculative=True)``).

MuJoCo detects contacts at the start of a step, from positions: a vertex moving at v
toward a surface is found only once it is inside, up to v h deep (a stiff cable whipping
down at 4.5 m/s went 41 mm into a floor at dt 1e-2). With a contact margin, rows are made
for surfaces nearer than it, and derods' reference correction makes such a row keep the
end-of-step position from crossing the surface (approached slowly, from crossing it deeper
than a resting vertex's fall in a step, :func:`sink_depth`, so that a resting rod touches),
no more (:func:`derods._numba.contact_reference.correct_aref`). A static margin must be chosen for
the fastest motion of the run; this one is set every step, per rod, to the travel of the
rod's fastest vertex in the step with room to spare (:data:`ROOM`), and never below the
static margin; a rod that travels no further in a step than a speculative row would let it
sink keeps the static margin (:meth:`SpeedMargin.update`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from .._numba.calls import Bound
from .._numba.contact_reference import speed_margins

#: A rod's margin is this times its fastest vertex's travel in the step, |v + h a0| h: the
#: velocity the unconstrained step takes (contacts and other bodies change it within the
#: step; the half to spare covers what they add).
ROOM = 1.5
#: [m/s^2] Standard gravity, the scale of the depth a speculative row lets a slowly
#: approaching vertex end its step inside the surface (:func:`sink_depth`): ROOM G0 h^2, a
#: resting vertex's fall in a step on Earth (15 um at dt 1e-3,
#: 1.5 mm at 1e-2; :func:`derods._numba.contact_reference.correct_aref`, which stops faster
#: ones at the surface), so that a rod resting or sliding on a surface touches it (a
#: contact with friction) from the next step. Kept from crossing at all, a resting vertex
#: stayed a hair above the surface, where a contact has no friction: a cable dragged along a
#: floor at 0.2 m/s, dt 1e-3, felt 0.76 (pyramidal) / 0.79 (elliptic) of Coulomb's kinetic
#: friction; 0.992 / 0.994 with it (1.0006 without a margin); the held sweep's dips at dt
#: 1e-2 stay gone (454 of 454).
G0 = 9.81


def sink_depth(h: float) -> float:
    """The depth [m] a speculative row lets a vertex end a step of h [s] inside its
    surface (:data:`G0`)."""
    return ROOM * G0 * h * h


class SpeedMargin:
    """Each step, the contact margin [m] (its flex's ``flex_margin``) of every rod in
    ``rods`` set to max(static margin, ROOM |v + h a0|_max h) over its free vertices.

    model: the compiled world's; flexes (n_rods,): each rod's flex id; rod_of_place
    (n_places,): each free vertex's rod; static [m]: the margin the rods were compiled with;
    rods: the rods whose margins follow their speed (the others keep the static one).
    """

    def __init__(self, model: mujoco.MjModel, flexes: np.ndarray, rod_of_place: np.ndarray, static: float,
                 rods: np.ndarray):
        self.flexes = np.asarray(flexes, dtype=np.int64)
        self.rod_of_place = np.asarray(rod_of_place, dtype=np.int64)
        self.static = float(static)
        self.h = float(model.opt.timestep)
        self.chosen = np.zeros(len(self.flexes), dtype=np.bool_)
        self.chosen[np.asarray(rods, dtype=np.int64)] = True
        self._kernel = Bound(speed_margins)
        self._flex_margin = model.flex_margin  # a view of the model's, written in place
        self.sink = sink_depth(self.h)

    def update(self, v: np.ndarray, a0: np.ndarray) -> bool:
        """Set the margins for the step from the rods' velocities v (n,) [m/s] and their
        unconstrained accelerations a0 (n,) [m/s^2], both over the free dofs; returns
        whether any is > 0. A rod whose fastest vertex travels no further in the step than
        a speculative row would let it sink (:func:`sink_depth`; a resting rod travels
        g h^2) keeps the static margin: its rows would let it in as far as it goes anyway,
        and a resting rod makes no rows ahead of it and its step no correction of them (a
        cable lying on a floor held by a cart with dofs: 195 us a step with the margin
        always on, 161 without, as without speculation)."""
        return self._kernel(v, a0, self.h, self.rod_of_place, self.chosen, self.static, ROOM, self.sink,
                            self.flexes, self._flex_margin)

