"""Compiled mirror of :mod:`derods.sim.coupled`: where the held vertices go.
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def holder_steps_into(qvel, dofs, aq, in_tree, h, out):
    """out (k,) <- h (qvel[dofs] + h aq[in_tree]) [m or rad]: how far MuJoCo's integrator
    moves the holder dofs ``dofs`` (k,) this step with their trees' acceleration aq (m,)
    (in_tree (k,): each dof's place in aq)."""
    for j in range(len(dofs)):
        out[j] = h * (qvel[dofs[j]] + h * aq[in_tree[j]])


@nb.njit(cache=True)
def moved_into(x, vertex, dx, out):
    """out (n_vertices, 3) <- x, the vertices ``vertex`` (H,) moved by dx (3H,) [m]."""
    out[:] = x
    for c in range(len(vertex)):
        for a in range(3):
            out[vertex[c], a] = x[vertex[c], a] + dx[3 * c + a]
