"""The curve a user edits: a composite cubic Bezier with C0 or C1 joins, and what it
looks like to the rod (samples at equal arc length, curvature, torsion).

A :class:`Curve` is frozen: each edit returns a new one, so an editor keeps a history
for free and a drawing never sees a half-made change. Segment s uses control points
3s .. 3s + 3 (neighbours share their end point, the "join"); a C1 join keeps its two
handles mirrored through it, P_{3s+1} = 2 P_{3s} - P_{3s-1}, which makes the tangent
continuous (direction and speed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import shapes

CONTINUITIES = ("C0", "C1")
#: Samples per segment of the dense polyline behind arc lengths (its chord error on a
#: segment bent by a quarter turn: ~1e-5 of the segment's length).
DENSE = 400


@dataclass(frozen=True)
class Curve:
    """points: control points [m], shape (3k + 1, 3), k >= 1 segments. joins: the
    continuity of each inner join ("C0" or "C1"), length k - 1. Build with
    :meth:`make`, which enforces the C1 joins."""

    points: np.ndarray
    joins: tuple[str, ...]

    @classmethod
    def make(cls, points, joins=None) -> "Curve":
        """A curve from control points (3k + 1, 3) [m] and per-join continuities (default
        all "C1"); each C1 join's outgoing handle is set to the mirror of its incoming one."""
        p = np.array(points, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 4 or (p.shape[0] - 1) % 3:
            raise ValueError(f"points must have shape (3k+1, 3) for k >= 1 cubic segments, got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("points has a NaN or infinite coordinate")
        k = (len(p) - 1) // 3
        joins = tuple(["C1"] * (k - 1) if joins is None else joins)
        if len(joins) != k - 1:
            raise ValueError(f"joins must give one continuity per inner join ({k - 1}), got {len(joins)}")
        for j, c in enumerate(joins):
            if c not in CONTINUITIES:
                raise ValueError(f"join {j + 1}: continuity must be 'C0' or 'C1', got {c!r}")
            if c == "C1":
                s = 3 * (j + 1)
                p[s + 1] = 2.0 * p[s] - p[s - 1]
        p.setflags(write=False)
        return cls(p, joins)

    @property
    def n_segments(self) -> int:
        return (len(self.points) - 1) // 3

    # -- edits ---------------------------------------------------------------------------
    def moved(self, index: int, position) -> "Curve":
        """Control point ``index`` moved to ``position`` [m]. A join or end point carries
        its handles along; a handle next to a C1 join turns the handle across the join
        with it (mirrored through the join), so the curve stays smooth there."""
        p = self.points.copy()
        n = len(p)
        if not -n <= index < n:
            raise IndexError(f"control point {index} out of range; the curve has {n}")
        i = index % n
        position = np.asarray(position, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"position must be 3 finite coordinates [m], got {position!r}")
        if i % 3 == 0:  # a join or an end: its handles go with it
            delta = position - p[i]
            for h in (i - 1, i + 1):
                if 0 <= h < n:
                    p[h] += delta
            p[i] = position
        else:
            p[i] = position
            join = i - 1 if i % 3 == 1 else i + 1
            s = join // 3
            if 0 < join < n - 1 and self.joins[s - 1] == "C1":
                across = 2 * join - i
                p[across] = 2.0 * p[join] - p[i]
        return Curve.make(p, self.joins)

    def with_join(self, join: int, continuity: str) -> "Curve":
        """Inner join ``join`` (1 .. k-1, between segments join-1 and join) set to "C0" or
        "C1" (C1 mirrors the incoming handle into the outgoing one)."""
        if not 1 <= join <= self.n_segments - 1:
            raise IndexError(f"join {join} out of range; inner joins are 1..{self.n_segments - 1}")
        joins = list(self.joins)
        joins[join - 1] = continuity
        return Curve.make(self.points, joins)

    def with_segment_added(self) -> "Curve":
        """One more segment after the last, continuing its tangent for the length of the
        last segment's chord, joined C1."""
        p = self.points
        end, handle = p[-1], p[-2]
        d = end - handle
        chord = float(np.linalg.norm(p[-1] - p[-4]))
        if np.linalg.norm(d) < 1e-12 * max(chord, 1e-300):
            d = p[-1] - p[-4]
        d = d / np.linalg.norm(d) * chord / 3.0
        new = np.array([end + d, end + 2 * d, end + 3 * d])
        return Curve.make(np.vstack([p, new]), self.joins + ("C1",))

    def with_segment_removed(self, segment: int) -> "Curve":
        """Segment ``segment`` removed (the curve keeps at least one): the last one is cut
        off; an inner or first one is dropped and its neighbours joined."""
        k = self.n_segments
        if k == 1:
            raise ValueError("the curve has one segment left; it cannot lose it")
        if not 0 <= segment < k:
            raise IndexError(f"segment {segment} out of range; the curve has {k}")
        p = self.points
        if segment == k - 1:
            return Curve.make(p[:-3], self.joins[:-1])
        if segment == 0:
            return Curve.make(p[3:], self.joins[1:])
        keep = np.r_[0:3 * segment + 1, 3 * segment + 4:len(p)]
        joins = self.joins[:segment - 1] + self.joins[segment:]
        return Curve.make(p[keep], joins)

    # -- what the rod sees ---------------------------------------------------------------
    def evaluate(self, u, derivative: int = 0) -> np.ndarray:
        """Point or derivative (order 0-3) at curve parameters u in [0, k] (segment s on
        [s, s + 1]); shape u.shape + (3,) [m per unit parameter^order]."""
        return shapes.bezier_eval(self.points, u, derivative)

    def arc_table(self) -> tuple[np.ndarray, np.ndarray]:
        """(u, s): curve parameters of a dense polyline (DENSE per segment) and the arc
        length [m] at each, shape (DENSE k + 1,)."""
        u = np.linspace(0.0, self.n_segments, DENSE * self.n_segments + 1)
        x = self.evaluate(u)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))])
        return u, s

    @property
    def length(self) -> float:
        """Arc length [m]."""
        return float(self.arc_table()[1][-1])

    def parameters_at(self, s) -> np.ndarray:
        """Curve parameters at arc lengths s [m] (clipped to the curve)."""
        u, arc = self.arc_table()
        return np.interp(np.clip(s, 0.0, arc[-1]), arc, u)

    def sample(self, n_edges: int) -> np.ndarray:
        """n_edges + 1 vertices [m] at equal arc length along the curve, shape (n + 1, 3)
        (equal edges of the dense polyline: :func:`derods.shapes.resample`)."""
        u, _ = self.arc_table()
        return shapes.resample(self.evaluate(u), n_edges)

    def curvature_torsion(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Curvature kappa [1/m] and torsion tau [1/m] of the curve at arc lengths s [m]:
        |r' x r''| / |r'|^3 and (r' x r'') . r''' / |r' x r''|^2 (0 where the curve is
        straight, where torsion is undefined). At a C0 corner the one-sided values of the
        segment after it."""
        u = self.parameters_at(s)
        d1, d2, d3 = (self.evaluate(u, k) for k in (1, 2, 3))
        cross = np.cross(d1, d2)
        c2 = np.einsum("...i,...i->...", cross, cross)
        speed = np.linalg.norm(d1, axis=-1)
        kappa = np.sqrt(c2) / np.maximum(speed, 1e-300) ** 3
        straight = c2 <= 1e-18 * np.maximum(speed, 1e-300) ** 6
        tau = np.where(straight, 0.0, np.einsum("...i,...i->...", cross, d3) / np.where(straight, 1.0, c2))
        return kappa, tau

    # -- files -----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"points": self.points.tolist(), "joins": list(self.joins)}

    @classmethod
    def from_dict(cls, d: dict) -> "Curve":
        if not isinstance(d, dict) or "points" not in d:
            raise ValueError("a curve needs 'points' (a list of [x, y, z] control points) and optionally 'joins'")
        return cls.make(d["points"], d.get("joins"))
