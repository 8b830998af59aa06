"""Compiled mirror of the sequential loop of :func:`derods.frames.bishop_frames`: a
director carried along a curve edge by edge (space-parallel transport). The loop
cannot be vectorized along the rod; compiled, a rod of 100 000 edges takes
milliseconds instead of seconds."""

from __future__ import annotations

import math

import numba as nb

from ..geometry import CHI_MIN


@nb.njit(cache=True)
def transport_along(t, out):
    """out[b, j] = the parallel transport of out[b, j - 1] from t[b, j - 1] to t[b, j],
    made perpendicular to t[b, j] and unit, for j >= 1 (out[b, 0] given). t, out: shape
    (n_curves, n_edges, 3); the formula is that of :func:`derods.frames.parallel_transport`."""
    for b in range(t.shape[0]):
        for j in range(1, t.shape[1]):
            p0, p1, p2 = t[b, j - 1, 0], t[b, j - 1, 1], t[b, j - 1, 2]
            c0, c1, c2 = t[b, j, 0], t[b, j, 1], t[b, j, 2]
            k0, k1, k2 = p1 * c2 - p2 * c1, p2 * c0 - p0 * c2, p0 * c1 - p1 * c0
            s0, s1, s2 = p0 + c0, p1 + c1, p2 + c2
            opc = max(0.5 * (s0 * s0 + s1 * s1 + s2 * s2), CHI_MIN)
            cc = opc - 1.0
            w0, w1, w2 = out[b, j - 1, 0], out[b, j - 1, 1], out[b, j - 1, 2]
            kw = (k0 * w0 + k1 * w1 + k2 * w2) / opc
            v0 = cc * w0 + (k1 * w2 - k2 * w1) + k0 * kw
            v1 = cc * w1 + (k2 * w0 - k0 * w2) + k1 * kw
            v2 = cc * w2 + (k0 * w1 - k1 * w0) + k2 * kw
            vt = v0 * c0 + v1 * c1 + v2 * c2
            v0, v1, v2 = v0 - vt * c0, v1 - vt * c1, v2 - vt * c2
            nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            out[b, j, 0], out[b, j, 1], out[b, j, 2] = v0 / nv, v1 / nv, v2 / nv
