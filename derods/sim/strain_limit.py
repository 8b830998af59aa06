"""The implicit step's strain limit (:class:`StrainLimit`): the rods a step would strain
beyond World's ``strain_limit`` projected back onto their rest lengths, and turning edges
onto the lengths the linearized step meant (:func:`derods._numba.projection.limit_strain`).
Rods held by bodies with dofs take it in the coupled solve (:mod:`derods.sim.coupled`,
:mod:`derods.sim.held_limit`)."""

from __future__ import annotations

import math

import numpy as np

from .._numba.projection import touching_into
from .projection import PROJECTION_MAX_ITER, PROJECTION_TOL

#: The implicit step's default strain limit [relative edge strain] (World's
#: ``strain_limit``). Its stiff stretching term is linearized, so an edge that turns by
#: phi in one step comes out stretched by ~phi^2 / 2 (a strand swung by a moving head:
#: 14 % at dt = 1e-2 s; a rod hitting the box at dt = 2e-3 s: 0.08 %). An inextensible
#: rod (the default stretch stiffness) whose predicted strain exceeds this is projected
#: back onto its rest lengths before contacts are solved; the tension a hanging rod holds
#: strains it far less (~1e-7), so a rod at rest is never projected.
STRAIN_LIMIT = 1e-3
#: Projecting after the contact solve moves a vertex a contact pushes on this much less
#: than its mass says. Held in place (0), two touching vertices the contact solve set too
#: far apart make the projection fail (300 shaken strands kept 4.6 % strain); moved
#: freely (1), they are pushed back into what they touch.
TOUCHING_WEIGHT = 1e-2


class StrainLimit:
    """The strain limit's part of the implicit step (:class:`derods.sim.integrators.Implicit`
    and the modes built on it), which it reads: rods, layout, entries, holders, contact,
    diagnosis, x, x_start, v, h, n_steps, data and ``_limit_kernel`` (the compiled limit,
    on threads where the world's rods are split: :meth:`Step.use_split`)."""

    def _limits_strain(self) -> None:
        """The strain limit's settings and buffers (at the step's construction)."""
        lay = self.layout
        #: Per rod, what the strain limit does (derods._numba.projection.limit_strain): open
        #: rods of the default (inextensible) stretch stiffness get their strain limited (1),
        #: and their turning edges kept at their first-order lengths too (2), but for rods held
        #: by bodies with dofs (there the projection keeps the held vertices where the coupled
        #: solve put them: run every step it took a free rod pinned to a free body 0.42 m/s of
        #: drift in momentum where it keeps it to 1e-9; those held at one end get their
        #: turning edges projected with their holders moving, derods.sim.held_limit.turn_held).
        self.limited = np.array([2 * (not e.rod.closed and e.rod.stretch_stiffness is None) for e in self.entries],
                                dtype=np.int8)
        self.limited[self.holders.rods if self.holders else []] //= 2
        #: After the contact solve only the limit itself (1): brought to their first-order
        #: lengths there too, the edges of a helix landing at 2.4 m/s pulled touching vertices
        #: 8 mm into the floor.
        self._limited_rest = np.minimum(self.limited, 1)
        self.inv_mass = np.zeros(len(lay.x0))
        self.inv_mass[lay.free_vertex] = 1.0 / lay.mass[0::3]
        self._xp = np.zeros_like(lay.x0)
        #: Rods projected back to their rest lengths in the last step (see STRAIN_LIMIT).
        self.n_projected = 0
        self.strain_limit = STRAIN_LIMIT

    def _touching(self) -> np.ndarray:
        """Inverse vertex masses with those a contact pushes on made TOUCHING_WEIGHT
        times lighter, so that projecting after the contact solve leaves them close to
        where it put them."""
        inv_mass = np.empty_like(self.inv_mass)
        touching_into(self.contact.force, self.inv_mass, self.layout.free_vertex, TOUCHING_WEIGHT, inv_mass)
        return inv_mass

    def _strain_limit_now(self) -> float:
        """The strain limit a step applies: World's ``strain_limit``, or inf (no projection
        runs) when it is inf or no rod is limited."""
        return self.strain_limit if self.limited.any() else math.inf

    def _limit_strain(self, a: np.ndarray, inv_mass: np.ndarray | None = None,
                      held_x: np.ndarray | None = None) -> tuple[int, int]:
        """Project the rods that ``a`` (local accelerations, changed in place) would strain
        beyond the strain limit back onto their rest lengths, moving vertices by
        ``inv_mass`` (n_vertices,) (default: their own), the held ones predicted at
        ``held_x`` (n_vertices, 3) [m] (default: where they are); returns how many were,
        and how many could not be (held taut between pins: they keep their step)."""
        if math.isinf(self._strain_limit_now()):
            return 0, 0
        held_x = self.x if held_x is None else held_x
        limited = self.limited if inv_mass is None else self._limited_rest

        def limit(weights: np.ndarray) -> tuple[int, int]:
            return self._limit_kernel(self.x_start, self.rods.v_off, self.rods.e_off, self.rods.rest_len, weights,
                                      self.layout.place, self.v, a, self.h, limited, self.strain_limit,
                                      PROJECTION_TOL, PROJECTION_MAX_ITER, self._xp, held_x)
        return self._projected(limit, self.inv_mass if inv_mass is None else inv_mass)

    def _projected(self, limit, weights: np.ndarray) -> tuple[int, int]:
        """``limit(weights)`` (a call of the strain limit's kernel with vertex weights
        (n_vertices,): (rods projected, rods left)), and the rods it left again by the
        vertices' own masses where ``weights`` are not those. Touching vertices made 100x
        lighter can leave the projection too ill-conditioned to converge (a cable jerked along
        a floor by a mocap cart, 5 mm edges moved 6 mm a step: 55 iterations, 4 with its own
        masses; a cable drawn over a ledge's edge in the alpha mode: never projected, 17 %
        strain, diverged at step 9): those rods are projected by their own masses instead,
        rather than kept strained."""
        n, left = 0, 0
        try:
            n, left = limit(weights)
            if left and weights is not self.inv_mass:
                more, left = limit(self.inv_mass)
                n += more
        except ValueError as err:  # the projection's banded Cholesky, in a state gone wild
            self.diagnosis.not_positive_definite(str(err), self.n_steps, self.data.time)
        return n, left
