"""The geometry of a MuJoCo 3.x cable composite, and the sections it reads, as derods needs them.

MuJoCo 3.x's ``<composite type="cable">`` lays ``count`` vertices on a curve (or takes
them from ``vertex``), puts one body per edge with its x axis along the edge, and
carries a normal along the cable by discrete parallel transport (the body frames).
derods keeps the vertices (they become the rod's), and the frames of the first and
last bodies (``B_first``, ``B_last``, which stay as real bodies holding the rod's end
edges) and of the first edge's normal (which orients a box section). The frames are
computed by the same arithmetic as MuJoCo's, including its behaviour on a straight
cable, whose normal vanishes (the frames are then whatever its matrix-to-quaternion
conversion makes of a frame with zero normal and binormal: the x axis still along the
edge).

Everything here is a pure function of numbers; units are the model's (metres).
"""

from __future__ import annotations

import math

import numpy as np

#: The curve shapes a composite's ``curve`` attribute names, per coordinate.
CURVE_SHAPES = ("s", "cos(s)", "sin(s)", "0")
#: MuJoCo's mjEPS: below this squared norm a vector is left as it is.
_EPS = 1e-14


def curve_vertices(curve: tuple[str, str, str], count: int, size, quat) -> np.ndarray:
    """Vertices [m] of a composite's ``curve``, shape (count, 3), in the composite's frame.

    curve: one of :data:`CURVE_SHAPES` per coordinate (x, y, z): "s" a line of length
    size[0]; "cos(s)", "sin(s)" size[1] cos / sin of pi size[2] s / size[0] (size[2] half
    turns over the cable); "0" zero. quat: (w, x, y, z) turning the curve (normalized
    as MuJoCo does for generated vertices only; like MuJoCo, not normalized).
    """
    size = np.asarray(size, dtype=float)
    k = np.arange(count) / (count - 1)
    cols = []
    for shape in curve:
        if shape == "s":
            cols.append(k * size[0])
        elif shape == "cos(s)":
            cols.append(size[1] * np.cos(math.pi * k * size[2]))
        elif shape == "sin(s)":
            cols.append(size[1] * np.sin(math.pi * k * size[2]))
        else:
            cols.append(np.zeros(count))
    v = np.column_stack(cols)
    return rotate(np.asarray(quat, dtype=float), v)


def rotate(quat, v: np.ndarray) -> np.ndarray:
    """Vectors v (..., 3) turned by the unit quaternion ``quat`` (w, x, y, z)."""
    w, q = float(quat[0]), np.asarray(quat[1:], dtype=float)
    t = 2.0 * np.cross(q, v)
    return v + w * t + np.cross(q, t)


def quat_to_mat(quat) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z); its columns are the frame's axes."""
    w, x, y, z = (float(c) for c in quat)
    return np.array([
        [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
    ])


def _normalize(v: np.ndarray) -> float:
    """MuJoCo's vector normalization, in place: a vector of squared norm below mjEPS is left
    as it is (and 0 returned); otherwise it is scaled to unit length and its norm returned."""
    n2 = float(v @ v)
    if n2 < _EPS:
        return 0.0
    n = math.sqrt(n2)
    if abs(n - 1.0) > _EPS:
        v /= n
    return n


def _frame_to_quat(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The quaternion (w, x, y, z) of the frame with axes x, y, z (Shepperd's method on the
    largest of the four candidates, as MuJoCo converts a frame; a degenerate frame gives the
    normalized result of the same arithmetic)."""
    m = (x, y, z)  # m[c][r]: column c, row r
    q = np.zeros(4)
    if m[0][0] + m[1][1] + m[2][2] > 0:
        q[0] = 0.5 * math.sqrt(1 + m[0][0] + m[1][1] + m[2][2])
        q[1] = 0.25 * (m[1][2] - m[2][1]) / q[0]
        q[2] = 0.25 * (m[2][0] - m[0][2]) / q[0]
        q[3] = 0.25 * (m[0][1] - m[1][0]) / q[0]
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        q[1] = 0.5 * math.sqrt(1 + m[0][0] - m[1][1] - m[2][2])
        q[0] = 0.25 * (m[1][2] - m[2][1]) / q[1]
        q[2] = 0.25 * (m[1][0] + m[0][1]) / q[1]
        q[3] = 0.25 * (m[2][0] + m[0][2]) / q[1]
    elif m[1][1] > m[2][2]:
        q[2] = 0.5 * math.sqrt(1 - m[0][0] + m[1][1] - m[2][2])
        q[0] = 0.25 * (m[2][0] - m[0][2]) / q[2]
        q[1] = 0.25 * (m[1][0] + m[0][1]) / q[2]
        q[3] = 0.25 * (m[2][1] + m[1][2]) / q[2]
    else:
        q[3] = 0.5 * math.sqrt(1 - m[0][0] - m[1][1] + m[2][2])
        q[0] = 0.25 * (m[0][1] - m[1][0]) / q[3]
        q[1] = 0.25 * (m[2][0] + m[0][2]) / q[3]
        q[2] = 0.25 * (m[2][1] + m[1][2]) / q[3]
    _normalize(q)
    return q


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    if angle == 0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    s = math.sin(0.5 * angle)
    return np.array([math.cos(0.5 * angle), axis[0] * s, axis[1] * s, axis[2] * s])


def body_frames(x: np.ndarray) -> np.ndarray:
    """Orientations (w, x, y, z) of the composite's bodies, one per edge, shape (n - 1, 4), in
    the composite's frame.

    x: the vertices [m], shape (n, 3), n >= 2. Each frame has its x axis along its edge;
    the first takes its binormal from the first two edges (t0 x t1), later ones carry
    the normal over by the rotation taking one tangent to the next.
    """
    x = np.asarray(x, dtype=float)
    n = len(x)
    normal = np.array([0.0, 1.0, 0.0])
    out = np.zeros((n - 1, 4))
    tprev = np.zeros(3)
    for i in range(n - 1):
        t = x[i + 1] - x[i]
        _normalize(t)
        if i == 0:
            tnext = np.zeros(3)
            if n > 2:
                tnext = x[2] - x[1]
                _normalize(tnext)
            b = np.cross(t, tnext)
            _normalize(b)
            normal = np.cross(b, t)
            _normalize(normal)
        else:
            b = np.cross(tprev, t)
            angle = math.atan2(_normalize(b), float(tprev @ t))
            normal = rotate(_axis_angle(b, angle), normal)
            _normalize(normal)
            b = np.cross(t, normal)
            _normalize(b)
        out[i] = _frame_to_quat(t, normal, b)
        tprev = t
    return out


def box_as_ellipse(h: float, w: float, shear: float, density: float) -> dict:
    """An elliptic section with a box section's stiffnesses and mass per length.

    h, w: the box's half sizes [m], each the ellipse's semi-axis direction's. The ellipse's
    semi-axes (a, b) = c (h, w), c = (16 / (3 pi))^(1/4), give the box's second moments
    pi a b^3 / 4 = (2w)^3 (2h) / 12 and pi a^3 b / 4 = (2h)^3 (2w) / 12 exactly; the shear
    modulus [Pa] is scaled so that G J matches MuJoCo's torsion constant of the rectangle,
    and the density [kg/m^3] so that rho A matches 4 h w rho. Returns the keyword
    arguments of :class:`derods.Material` but ``young``: radius, radius2, shear, density.
    """
    c = (16.0 / (3.0 * math.pi)) ** 0.25
    a, b = c * h, c * w
    return {"radius": a, "radius2": b, "shear": shear * box_torsion(h, w) / (math.pi * a**3 * b**3 / (a * a + b * b)),
            "density": density * 4.0 * h * w / (math.pi * a * b)}


def box_torsion(h: float, w: float) -> float:
    """Torsion constant J [m^4] of a rectangle of half sizes h, w, as MuJoCo's cable plugin
    takes it (Roark's approximation)."""
    a, b = max(h, w), min(h, w)
    return a * b**3 * (16.0 / 3.0 - 3.36 * b / a * (1.0 - b**4 / a**4 / 12.0))


def segment_mass(kind: str, size, length: float, density: float) -> float:
    """Mass [kg] MuJoCo gives one composite geom of ``length`` [m] from its density [kg/m^3]:
    a capsule (its two half-sphere caps included), a cylinder, or a box of half sizes
    size[1], size[2] across."""
    if kind == "capsule":
        r = size[0]
        return density * (math.pi * r * r * length + 4.0 / 3.0 * math.pi * r**3)
    if kind == "cylinder":
        return density * math.pi * size[0] ** 2 * length
    return density * 4.0 * size[1] * size[2] * length
