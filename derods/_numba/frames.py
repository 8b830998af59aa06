"""Compiled mirror of the sequential loop of :func:`derods.frames.bishop_frames`: a
director carried along a curve edge by edge (space-parallel transport). The loop
cannot be vectorized along the rod; compiled, a rod of 100 000 edges takes
milliseconds instead of seconds."""

from __future__ import annotations

import numba as nb

from .rod_geometry import transport


@nb.njit(cache=True)
def transport_along(t, out):
    """out[b, j] = the parallel transport of out[b, j - 1] from t[b, j - 1] to t[b, j],
    made perpendicular to t[b, j] and unit, for j >= 1 (out[b, 0] given). t, out: shape
    (n_curves, n_edges, 3); the formula is that of :func:`derods.frames.parallel_transport`."""
    for b in range(t.shape[0]):
        for j in range(1, t.shape[1]):
            out[b, j, 0], out[b, j, 1], out[b, j, 2] = transport(
                t[b, j - 1, 0], t[b, j - 1, 1], t[b, j - 1, 2], t[b, j, 0], t[b, j, 1], t[b, j, 2],
                out[b, j - 1, 0], out[b, j - 1, 1], out[b, j - 1, 2])
