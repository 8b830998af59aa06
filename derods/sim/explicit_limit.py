"""The explicit step's stability limit: the largest dt [s] at which applying the elastic
force explicitly (World(mode="explicit")) stays stable, estimated at the start; the "auto"
mode picks the implicit step beyond it."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from ..step import EndBodies, Frames, RodSet, Terms, evaluate
from .layout import Layout, RodEntry


def explicit_dt_limit(entries: list[RodEntry], layout: Layout, rods: RodSet, frames: Frames, ends: EndBodies,
                      data: mujoco.MjData) -> float:
    """The explicit step's stability limit [s] at the start: 2 / omega_max of the stiffest
    rod, omega_max^2 bounded by Gershgorin on M^-1 K (rows of |K| over the free dofs, the
    twist term's c |g| sum|g| added). ``frames`` are not changed."""
    terms = Terms.empty(rods.n_rods, rods.n_vertices, layout.n, layout.band_rows)
    evaluate(rods, frames.copy(), layout.x0.copy(), layout.place, terms, ends, data.xmat)
    row = _abs_row_sums(terms.band)
    for i in range(rods.n_rods):
        if terms.coef[i] > 0:
            lo, hi = layout.dof_off[i], layout.dof_off[i + 1]
            g = np.abs(terms.g_tw[layout.free_vertex[lo // 3:hi // 3]].ravel())
            row[lo:hi] += terms.coef[i] * g * g.sum()
    w2 = np.max(row / layout.mass) if layout.n else 0.0
    return 2.0 / math.sqrt(w2) if w2 > 0 else math.inf


def _abs_row_sums(band: np.ndarray) -> np.ndarray:
    """Row sums of |H| for symmetric H given by its lower band."""
    ab = np.abs(band)
    row = ab.sum(axis=0)
    for d in range(1, ab.shape[0]):
        row[d:] += ab[d, :-d]
    return row
