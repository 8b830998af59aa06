"""What changes during a run of a rod (:class:`RodState`), and what one implicit step
takes from it (:class:`StepTerms`, from :meth:`derods.Rod.step_terms`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import twist


@dataclass
class RodState:
    """What changes during a run.

    x: vertex positions [m], shape (..., n_vertices, 3).
    u: reference directors, perpendicular to ``t``, shape (..., n_edges, 3).
    t: unit tangents at which ``u`` was last transported, shape (..., n_edges, 3).
    theta: twist angles of the material frames [rad], shape (..., n_edges).
    """

    x: np.ndarray
    u: np.ndarray
    t: np.ndarray
    theta: np.ndarray


@dataclass
class StepTerms:
    """What one implicit step needs from a rod, from :meth:`derods.Rod.step_terms`; every field
    is set on every path.

    state: the new state (frames transported, twist solved).
    energy: elastic energy [J], shape (...).
    grad_x: dE/dx [N], shape (..., n_vertices, 3) (the elastic force is minus this).
    hessian_banded: positive semi-definite Hessian of stretch + bending in the lower
        banded form of :func:`scipy.linalg.solveh_banded`, shape (..., 9, 3 n_vertices);
        for a ring, with its vertices in :func:`derods.stencil.ring_order` (where its
        Hessian is banded), shape (..., RING_BANDWIDTH + 1, 3 n_vertices).
    twist: the reduced twist term (:class:`derods.twist.ReducedTwist`), whose Hessian
        c g g^T is a rank-one update of ``hessian_banded``; zero (lam = c = 0, g = 0)
        for a rod without the twist term, or whose twist is solved by Newton's method
        (anisotropic or naturally curved rods: their twist stiffness is not rank one).
    grad_theta: dE/dtheta [N m] at the solved twist angles, shape (..., n_edges): zero
        on free angles; on the held end angles, the moments the clamps resist.
    """

    state: RodState
    energy: np.ndarray
    grad_x: np.ndarray
    hessian_banded: np.ndarray
    twist: twist.ReducedTwist
    grad_theta: np.ndarray
