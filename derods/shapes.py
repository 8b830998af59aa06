"""Rod shapes: straight, circle, helix, polylines and piecewise cubic Bezier curves.

Every function returns vertex positions [m] of shape (n_vertices, 3): n_edges + 1
vertices for an open rod, n_edges for a closed one. Curves are sampled at
equal arc length, so all edges have the same arc length; their chords are then
equal up to a relative O((h kappa)^2) (exactly equal on circles and helices).
"""

from __future__ import annotations

import numpy as np

from . import validation

_SAMPLES_PER_SEGMENT = 512  # dense samples per Bezier segment for the arc-length table


def _count(name: str, n: int, minimum: int) -> int:
    return validation.integer(name, n, ge=minimum)


def _unit(name: str, v) -> np.ndarray:
    v = validation.vector(name, v, 3, nonzero=True)
    return v / np.linalg.norm(v)


def straight(length: float, n_edges: int, start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0)) -> np.ndarray:
    """A straight rod of ``length`` [m] from ``start`` [m] along ``direction``."""
    validation.positive("length", length, "m")
    n = _count("n_edges", n_edges, 2)
    d = _unit("direction", direction)
    start = validation.vector("start", start, 3, "m")
    s = np.linspace(0.0, length, n + 1)
    return start + s[:, None] * d


def _plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(normal, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(normal, a)


def circle(radius: float, n_edges: int, center=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A closed ring of ``radius`` [m] in the plane through ``center`` normal to ``normal``."""
    validation.positive("radius", radius, "m")
    n = _count("n_edges", n_edges, 3)
    a, b = _plane_basis(_unit("normal", normal))
    center = validation.vector("center", center, 3, "m")
    phi = 2.0 * np.pi * np.arange(n) / n
    return center + radius * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)


def helix(radius: float, pitch: float, turns: float, n_edges: int, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A right-handed circular helix about +z.

    radius [m]; pitch: rise per turn [m] (negative for left-handed); turns: number
    of turns. Curvature radius / (radius^2 + c^2), torsion c / (radius^2 + c^2)
    with c = pitch / (2 pi).
    """
    validation.positive("radius", radius, "m")
    validation.positive("turns", turns)
    validation.real("pitch", pitch, "m", example=0.05)
    n = _count("n_edges", n_edges, 2)
    start = validation.vector("start", start, 3, "m")
    phi = np.linspace(0.0, 2.0 * np.pi * turns, n + 1)
    c = pitch / (2.0 * np.pi)
    pts = np.stack([radius * np.cos(phi), radius * np.sin(phi), c * phi], axis=1)
    return pts - pts[0] + start


def resample(points, n_edges: int, closed: bool = False) -> np.ndarray:
    """Resample a polyline to ``n_edges`` edges of equal length along the polyline.

    points: polyline vertices [m], shape (m, 3); a closed polyline does not
    repeat its first point.
    """
    p = validation.points("points", points, validation.boolean("closed", closed))
    n = _count("n_edges", n_edges, 3 if closed else 2)
    if closed:
        p = np.concatenate([p, p[:1]], axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    target = np.linspace(0.0, s[-1], n + 1)
    out = np.stack([np.interp(target, s, p[:, k]) for k in range(3)], axis=1)
    return out[:-1] if closed else out


def bezier_control_points(control_points, continuity: str = "C1") -> np.ndarray:
    """Control points of a composite cubic Bezier curve, made C1 where asked.

    control_points: shape (3 k + 1, 3) for k segments; segment s uses points
    3s .. 3s + 3, so neighbouring segments share their end point.
    continuity: "C0" keeps the points as given (joins may corner); "C1"
    replaces the first inner point of every following segment by the mirror
    of the last inner point of the segment before it, P_{3s+1} = 2 P_{3s} -
    P_{3s-1}, which makes the tangent continuous exactly.
    Returns the control points actually used, shape (3 k + 1, 3).
    """
    p = np.array(validation.numeric_array("control_points", control_points), dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 4 or (p.shape[0] - 1) % 3:
        raise validation.InvalidInputError(
            f"control_points must have shape (3k+1, 3) for k >= 1 cubic segments, got {p.shape}"
        )
    if not np.all(np.isfinite(p)):
        raise validation.InvalidInputError("control_points has a NaN or infinite coordinate: pass finite points")
    validation.choice("continuity", continuity, ("C0", "C1"))
    k = (p.shape[0] - 1) // 3
    scale = max(float(np.max(np.ptp(p, axis=0))), 1e-300)
    for s in range(k):
        seg = p[3 * s : 3 * s + 4]
        if np.max(np.linalg.norm(seg - seg[0], axis=1)) <= 1e-12 * scale:
            raise validation.InvalidInputError(
                f"control_points: Bezier segment {s} is degenerate: control points {3 * s}..{3 * s + 3} coincide; "
                "move them apart"
            )
    if continuity == "C1":
        for s in range(1, k):
            j = 3 * s
            if np.linalg.norm(p[j] - p[j - 1]) <= 1e-12 * scale:
                raise validation.InvalidInputError(
                    f"control_points: C1 join {s}: control point {j - 1} coincides with join point {j}, so the "
                    "tangent there is undefined; move it or use continuity='C0'"
                )
            p[j + 1] = 2.0 * p[j] - p[j - 1]
    return p


def bezier_eval(control_points: np.ndarray, u: np.ndarray, derivative: int = 0) -> np.ndarray:
    """Point (or derivative of order 1-3) of a composite cubic Bezier curve.

    control_points: shape (3k + 1, 3). u: curve parameter in [0, k], segment
    s covering [s, s + 1], any shape. Returns shape u.shape + (3,).
    """
    p = validation.numeric_array("control_points", control_points)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 4 or (p.shape[0] - 1) % 3:
        raise validation.InvalidInputError(f"control_points must have shape (3k+1, 3), got {p.shape}")
    k = (p.shape[0] - 1) // 3
    u = validation.numeric_array("u", u)
    if not np.all(np.isfinite(u)):
        raise validation.InvalidInputError("u must be finite (the curve parameter in [0, k]): pass finite values")
    s = np.clip(np.floor(u).astype(int), 0, k - 1)
    w = (u - s)[..., None]
    p0, p1, p2, p3 = (p[3 * s + i] for i in range(4))
    if derivative == 0:
        return (1 - w) ** 3 * p0 + 3 * (1 - w) ** 2 * w * p1 + 3 * (1 - w) * w**2 * p2 + w**3 * p3
    if derivative == 1:
        return 3 * ((1 - w) ** 2 * (p1 - p0) + 2 * (1 - w) * w * (p2 - p1) + w**2 * (p3 - p2))
    if derivative == 2:
        return 6 * ((1 - w) * (p2 - 2 * p1 + p0) + w * (p3 - 2 * p2 + p1))
    if derivative == 3:
        return 6 * (p3 - 3 * p2 + 3 * p1 - p0) + 0 * w
    validation.refuse("derivative", "0, 1, 2 or 3", derivative)


def bezier(control_points, n_edges: int, continuity: str = "C1") -> np.ndarray:
    """A rod along a composite cubic Bezier curve, resampled to ``n_edges`` edges of equal arc length.

    control_points: [m], shape (3k + 1, 3); see :func:`bezier_control_points`
    for how ``continuity`` ("C0" or "C1") treats them.
    Returns vertex positions [m], shape (n_edges + 1, 3); a join of segments
    falls on a vertex only by chance.
    """
    n = _count("n_edges", n_edges, 2)
    p = bezier_control_points(control_points, continuity)
    k = (p.shape[0] - 1) // 3
    u = np.linspace(0.0, k, k * _SAMPLES_PER_SEGMENT + 1)
    # Arc length by Simpson's rule on the speed |B'(u)| between samples.
    mid = 0.5 * (u[1:] + u[:-1])
    speed = lambda v: np.linalg.norm(bezier_eval(p, v, 1), axis=-1)  # noqa: E731
    ds = (u[1:] - u[:-1]) / 6.0 * (speed(u[:-1]) + 4.0 * speed(mid) + speed(u[1:]))
    s = np.concatenate([[0.0], np.cumsum(ds)])
    target = np.linspace(0.0, s[-1], n + 1)
    return bezier_eval(p, np.interp(target, s, u))


def cantilever(length: float, n_edges: int, start=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0),
               clamped_ends: int = 1) -> np.ndarray:
    """A straight rod to be clamped at ``start`` (and at its far end), clamps at edge middles.

    A discrete clamp holds a whole edge, and acts where the material frame of
    that edge sits: at its middle. So the first edge reaches h/2 into the clamp
    and the rod extends ``length`` [m] beyond ``start``: h = length / (n - 1/2).
    With ``clamped_ends=2`` the last edge reaches h/2 into a second clamp at
    distance ``length``: h = length / (n - 1). With lumped masses this makes the
    static tip error O(h^2) instead of O(h).
    Returns vertex positions [m], shape (n_edges + 1, 3).
    """
    validation.positive("length", length, "m")
    n = _count("n_edges", n_edges, 2)
    d = _unit("direction", direction)
    if validation.integer("clamped_ends", clamped_ends) not in (1, 2):
        validation.refuse("clamped_ends", "1 or 2", clamped_ends)
    start = validation.vector("start", start, 3, "m")
    h = length / (n - 0.5) if clamped_ends == 1 else length / (n - 1)
    s = -0.5 * h + h * np.arange(n + 1)
    return start + s[:, None] * d


def overhand_knot(scale: float = 0.02, tail: float = 0.2, n_edges: int = 100,
                  height: float = 0.5) -> np.ndarray:
    """A loose overhand knot lying flat: a trefoil opened at its outermost lobe, with tails.

    The trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, -sin 3t) times ``scale`` [m] is cut
    open where it reaches farthest from its axis, and radial tails of length ``tail``
    [m] are added to both cut ends, so closing the tails far away gives back a trefoil.
    Returns ``n_edges`` + 1 vertices [m] at equal arc length, lifted by ``height`` [m].
    """
    validation.positive("scale", scale, "m")
    validation.positive("tail", tail, "m")
    validation.real("height", height, "m", example=0.5)
    t0, cut = np.pi / 3, 0.35
    t = np.linspace(t0 + cut, t0 + 2 * np.pi - cut, 400)
    c = np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)], 1) * scale

    def outward(p):
        v = np.array([p[0], p[1], 0.0])
        return v / np.linalg.norm(v)

    head = np.stack([c[0] + outward(c[0]) * s for s in np.linspace(tail, 0, 40, endpoint=False)])
    foot = np.stack([c[-1] + outward(c[-1]) * s for s in np.linspace(0, tail, 41)[1:]])
    return resample(np.concatenate([head, c, foot]), n_edges) + (0.0, 0.0, height)
