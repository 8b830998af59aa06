"""Centerline geometry of a discrete rod (Bergou et al. 2008, section 4.1).

Conventions used throughout derods:

* An open rod has ``n`` edges and ``n + 1`` vertices ``x_0 .. x_n``; a closed rod
  has ``n`` edges and ``n`` vertices, edge ``j`` joining ``x_j`` and ``x_{(j+1) % n}``.
* Edge ``j`` is ``e^j = x_{j+1} - x_j``.
* A *joint* is a vertex where two edges meet and the rod can bend: the interior
  vertices ``1 .. n-1`` of an open rod (``n - 1`` joints), every vertex of a
  closed rod (``n`` joints). Joint ``k`` sits between edges ``prev`` and
  ``next`` (:func:`joint_edge_index`) and its stencil is the three vertices
  ``(prev vertex, joint vertex, next vertex)`` (:func:`joint_vertex_index`).
* A joint bends by Bergou's curvature binormal ``kb`` (|kb| = 2 tan(phi / 2)) or,
  for rods with ``bending="angle"``, by the turning angle (:class:`TurningAngle`,
  |kb_angle| = phi); :func:`curvature` gives the one a rod takes.
* Every function accepts leading batch dimensions, so ``x`` of shape
  ``(n_rods, n_vertices, 3)`` evaluates many rods of equal size in one call.
"""

from __future__ import annotations

import numpy as np

#: Floor on chi = 1 + cos(turning angle). Two edges folded back onto each other
#: (turning angle -> pi) make the curvature binormal 2 tan(phi / 2) infinite;
#: the floor keeps energies and forces finite for turning angles within about
#: 1.4e-6 rad of pi, where the bending energy is already ~1e12 alpha / l.
CHI_MIN = 1e-12

#: The measures of bending a rod may take (:class:`derods.Rod`'s ``bending``): "tan",
#: Bergou's curvature binormal kb, |kb| = 2 tan(phi / 2); "angle", the turning angle
#: itself, kb_angle = phi kb / |kb| (:class:`TurningAngle`).
BENDING_MEASURES = ("tan", "angle")
#: Below this |kb| the turning angle's factors (:func:`turning_angle_factors`) are summed
#: as their series in y = |kb|^2 / 4: their closed forms lose about eps / |kb|^4 (relative)
#: to cancellation (measured against extended precision: at most 2e-14 from 0.5 up, where
#: the series' first neglected term, summed to ANGLE_SERIES_TERMS, is below 1e-17).
ANGLE_SERIES_MAX = 0.5
#: Terms of those series after the constant (y <= 1/16 where they are used).
ANGLE_SERIES_TERMS = 16


def edges(x: np.ndarray, closed: bool) -> np.ndarray:
    """Edge vectors e^j = x_{j+1} - x_j [m].

    x: vertex positions [m], shape (..., n_vertices, 3).
    Returns shape (..., n_edges, 3).
    """
    if closed:
        return np.roll(x, -1, axis=-2) - x
    return x[..., 1:, :] - x[..., :-1, :]


def n_edges(n_vertices: int, closed: bool) -> int:
    """Number of edges of a rod with ``n_vertices`` vertices."""
    return n_vertices if closed else n_vertices - 1


def n_joints(n_vertices: int, closed: bool) -> int:
    """Number of bending joints of a rod with ``n_vertices`` vertices."""
    return n_vertices if closed else n_vertices - 2


def joint_edge_index(n_edges_: int, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Indices (prev, next) of the two edges meeting at each joint, shape (n_joints,)."""
    if closed:
        nxt = np.arange(n_edges_)
        return (nxt - 1) % n_edges_, nxt
    return np.arange(n_edges_ - 1), np.arange(1, n_edges_)


def joint_vertex_index(n_vertices: int, closed: bool) -> np.ndarray:
    """Vertex indices of each joint's stencil (prev, joint, next), shape (n_joints, 3)."""
    if closed:
        k = np.arange(n_vertices)
        return np.stack([(k - 1) % n_vertices, k, (k + 1) % n_vertices], axis=1)
    k = np.arange(1, n_vertices - 1)
    return np.stack([k - 1, k, k + 1], axis=1)


def joint_pairs(e: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """The edges (e_prev, e_next) meeting at each joint, each shape (..., n_joints, 3)."""
    if closed:
        return np.roll(e, 1, axis=-2), e
    return e[..., :-1, :], e[..., 1:, :]


def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis."""
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def voronoi_len(rest_edge_len: np.ndarray, closed: bool) -> np.ndarray:
    """Vertex length l_k = |ebar^{prev}| + |ebar^{next}| of each joint [m].

    This is *twice* the Voronoi length of the joint, as in Bergou et al. 2008:
    with it, sum_k alpha |kb_k|^2 / l_k tends to (1/2) int alpha kappa^2 ds.

    rest_edge_len: rest edge lengths [m], shape (..., n_edges).
    Returns shape (..., n_joints).
    """
    if closed:
        return np.roll(rest_edge_len, 1, axis=-1) + rest_edge_len
    return rest_edge_len[..., :-1] + rest_edge_len[..., 1:]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]x with [v]x w = v x w; v shape (..., 3) -> (..., 3, 3)."""
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


class JointGeometry:
    """Per-joint quantities shared by every bending and twisting term.

    Computed once per evaluation from the current edges; attributes, each with
    leading shape (..., n_joints):

    * ``la``, ``lb``: lengths of the previous and next edge [m].
    * ``ta``, ``tb``: their unit tangents, shape (..., n_joints, 3).
    * ``chi``: 1 + cos(turning angle), computed as |ta + tb|^2 / 2 so that it
      stays accurate near a hairpin fold; floored at :data:`CHI_MIN`.
    * ``kb``: curvature binormal 2 (e_prev x e_next) / (|e_prev||e_next| +
      e_prev . e_next) (Bergou et al. 2008, eq. 1), dimensionless, |kb| = 2 tan(phi/2).
    """

    __slots__ = ("la", "lb", "ta", "tb", "chi", "kb", "_ja", "_jb")

    def __init__(self, e_prev: np.ndarray, e_next: np.ndarray):
        self.la = norm(e_prev)
        self.lb = norm(e_next)
        self.ta = e_prev / self.la[..., None]
        self.tb = e_next / self.lb[..., None]
        s = self.ta + self.tb
        self.chi = np.maximum(0.5 * np.einsum("...i,...i->...", s, s), CHI_MIN)
        self.kb = 2.0 * np.cross(self.ta, self.tb) / self.chi[..., None]
        self._ja = None
        self._jb = None

    @property
    def turning_angle(self) -> np.ndarray:
        """Turning angle phi [rad], in [0, pi], shape (..., n_joints)."""
        return 2.0 * np.arctan(0.5 * norm(self.kb))

    def jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """d kb / d e_prev and d kb / d e_next [1/m], each shape (..., n_joints, 3, 3).

        d kb/d e_prev = (-2 [tb]x - kb (ta + tb)^T) / (|e_prev| chi),
        d kb/d e_next = ( 2 [ta]x - kb (ta + tb)^T) / (|e_next| chi).
        """
        if self._ja is None:
            s = self.ta + self.tb
            outer = self.kb[..., :, None] * s[..., None, :]
            self._ja = (-2.0 * skew(self.tb) - outer) / (self.la * self.chi)[..., None, None]
            self._jb = (2.0 * skew(self.ta) - outer) / (self.lb * self.chi)[..., None, None]
        return self._ja, self._jb

    def jacobian_ab(self) -> np.ndarray:
        """d kb / d (e_prev, e_next), shape (..., n_joints, 3, 6)."""
        ja, jb = self.jacobians()
        return np.concatenate([ja, jb], axis=-1)

    def kb_hessian_dot(self, w: np.ndarray) -> np.ndarray:
        """sum_k w_k d^2 kb_k / d(e_prev, e_next)^2 [1/m^2], shape (..., n_joints, 6, 6).

        w: weights, shape (..., n_joints, 3). With s = w . (a x b),
        D = |a||b| + a . b and phi = w . kb = 2 s / D (a = e_prev, b = e_next):
        H = 2/D H_s - 2/D^2 (g_s g_D^T + g_D g_s^T) + 2 phi/D^2 g_D g_D^T - phi/D H_D.
        """
        la, lb = self.la[..., None], self.lb[..., None]
        a, b = self.ta * la, self.tb * lb
        d = (self.la * self.lb * self.chi)[..., None, None]
        phi = np.einsum("...i,...i->...", w, self.kb)[..., None, None]
        s = self.ta + self.tb
        g_s = np.concatenate([np.cross(b, w), np.cross(w, a)], axis=-1)
        g_d = np.concatenate([lb * s, la * s], axis=-1)
        eye = np.eye(3)
        shape = w.shape[:-1] + (6, 6)
        h_s = np.zeros(shape)
        ws = skew(w)
        h_s[..., :3, 3:] = -ws
        h_s[..., 3:, :3] = ws
        h_d = np.empty(shape)
        tata = self.ta[..., :, None] * self.ta[..., None, :]
        tbtb = self.tb[..., :, None] * self.tb[..., None, :]
        h_d[..., :3, :3] = (lb / la)[..., None] * (eye - tata)
        h_d[..., 3:, 3:] = (la / lb)[..., None] * (eye - tbtb)
        ab = eye + self.ta[..., :, None] * self.tb[..., None, :]
        h_d[..., :3, 3:] = ab
        h_d[..., 3:, :3] = np.swapaxes(ab, -1, -2)
        gsd = g_s[..., :, None] * g_d[..., None, :]
        return (
            (2.0 / d) * h_s
            - (2.0 / d**2) * (gsd + np.swapaxes(gsd, -1, -2))
            + (2.0 * phi / d**2) * (g_d[..., :, None] * g_d[..., None, :])
            - (phi / d) * h_d
        )


def turning_angle_factors(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(g, g' / x, (g' / x)' / x) of g(x) = 2 atan(x / 2) / x, the factor that turns Bergou's
    kb (|kb| = x = 2 tan(phi / 2)) into the turning angle's, kb_angle = g kb (|kb_angle| = phi).

    x: |kb|, dimensionless, any shape (>= 0). With y = x^2 / 4 and G(y) = atan(sqrt y) / sqrt y
    = sum_m (-y)^m / (2 m + 1): g = G, g' / x = G' / 2, (g' / x)' / x = G'' / 4, smooth at 0
    (1, -1/6, 1/10); summed as series below :data:`ANGLE_SERIES_MAX`, in closed form above.
    Each returned with the shape of x.
    """
    x = np.asarray(x, dtype=float)
    y = 0.25 * x * x
    small = x < ANGLE_SERIES_MAX
    g_s, a_s, b_s = np.zeros_like(y), np.zeros_like(y), np.zeros_like(y)
    for m in range(ANGLE_SERIES_TERMS, -1, -1):  # Horner, from the highest power of y
        sign = -1.0 if m % 2 else 1.0
        g_s = g_s * y + sign / (2 * m + 1)
        if m >= 1:
            a_s = a_s * y + sign * m / (2 * m + 1)
        if m >= 2:
            b_s = b_s * y + sign * m * (m - 1) / (2 * m + 1)
    yc = np.where(small, 1.0, y)  # the closed forms where they are used (no 0 / 0 elsewhere)
    root = np.sqrt(yc)
    g_c = np.arctan(root) / root
    c = 1.0 / (1.0 + yc)  # d phi / d x
    a_c = (c - g_c) / (4.0 * yc)
    b_c = (-0.5 * c * c - 3.0 * a_c) / (4.0 * yc)
    return np.where(small, g_s, g_c), np.where(small, 0.5 * a_s, a_c), np.where(small, 0.25 * b_s, b_c)


class TurningAngle:
    """The turning angle as the curvature of each joint: kb_angle = phi kb / |kb|, |kb_angle| =
    phi [rad], in place of Bergou's kb (|kb| = 2 tan(phi / 2)); its direction is kb's.

    It has :class:`JointGeometry`'s interface for bending (``kb``, :meth:`jacobians`,
    :meth:`jacobian_ab`, :meth:`kb_hessian_dot`, and the edges' ``la``, ``lb``, ``ta``,
    ``tb``, ``chi``), so the bending energies take either. kb_angle = g(x) kb with x = |kb|,
    g = 2 atan(x / 2) / x (:func:`turning_angle_factors`), and by the chain rule
    d kb_angle / d kb = G = g I + (g' / x) kb kb^T. An arc of constant curvature kappa
    sampled by edges of length h turns by exactly kappa h at every joint, so a rod under a
    constant moment M turns by M h / alpha per joint (MuJoCo's cable measures bending so);
    Bergou's tan(phi / 2) would need alpha phi (1 + phi^2 / 3) / h for it.
    """

    __slots__ = ("base", "la", "lb", "ta", "tb", "chi", "kb", "_g", "_a", "_b", "_ja", "_jb")

    def __init__(self, jg: JointGeometry):
        self.base = jg
        self.la, self.lb, self.ta, self.tb, self.chi = jg.la, jg.lb, jg.ta, jg.tb, jg.chi
        self._g, self._a, self._b = turning_angle_factors(norm(jg.kb))
        self.kb = self._g[..., None] * jg.kb
        self._ja = None
        self._jb = None

    @property
    def turning_angle(self) -> np.ndarray:
        """Turning angle phi [rad], in [0, pi], shape (..., n_joints)."""
        return self.base.turning_angle

    def _times_g(self, m: np.ndarray) -> np.ndarray:
        """G m for G = d kb_angle / d kb = g I + a kb kb^T and m of shape (..., n_joints, 3, c)."""
        kb = self.base.kb
        kb_m = np.einsum("...k,...kc->...c", kb, m)
        return self._g[..., None, None] * m + self._a[..., None, None] * kb[..., :, None] * kb_m[..., None, :]

    def jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """d kb_angle / d e_prev and d kb_angle / d e_next [1/m], each (..., n_joints, 3, 3): G times
        :meth:`JointGeometry.jacobians`."""
        if self._ja is None:
            ja, jb = self.base.jacobians()
            self._ja, self._jb = self._times_g(ja), self._times_g(jb)
        return self._ja, self._jb

    def jacobian_ab(self) -> np.ndarray:
        """d kb_angle / d (e_prev, e_next), shape (..., n_joints, 3, 6)."""
        ja, jb = self.jacobians()
        return np.concatenate([ja, jb], axis=-1)

    def kb_hessian_dot(self, w: np.ndarray) -> np.ndarray:
        """sum_k w_k d^2 kb_angle_k / d(e_prev, e_next)^2 [1/m^2], shape (..., n_joints, 6, 6).

        w: weights, shape (..., n_joints, 3). f = w . kb_angle = g(x) (w . kb) has, over kb,
        the gradient G w and the Hessian H_f = a (w kb^T + kb w^T) + a (w . kb) I
        + b (w . kb) kb kb^T (a = g' / x, b = a' / x), so the chain rule gives
        J^T H_f J + sum_k (G w)_k d^2 kb_k (J = d kb / d(e_prev, e_next)).
        """
        kb = self.base.kb
        a, b = self._a[..., None, None], self._b[..., None, None]
        wk = np.einsum("...i,...i->...", w, kb)[..., None, None]
        h_f = (a * (w[..., :, None] * kb[..., None, :] + kb[..., :, None] * w[..., None, :]) + a * wk * np.eye(3)
               + b * wk * kb[..., :, None] * kb[..., None, :])
        j = self.base.jacobian_ab()
        gw = self._times_g(w[..., None])[..., 0]
        return np.einsum("...ki,...kl,...lj->...ij", j, h_f, j) + self.base.kb_hessian_dot(gw)


def curvature(jg: JointGeometry, bending: str = "tan"):
    """The curvature a rod bends by at its joints: ``jg`` itself for Bergou's measure
    ("tan"), its :class:`TurningAngle` for "angle" (:data:`BENDING_MEASURES`). The
    reference twist keeps Bergou's kb either way: its gradient, kb / (2 |e|), is the
    holonomy of parallel transport, not a measure of bending."""
    if bending == "tan":
        return jg
    if bending == "angle":
        return TurningAngle(jg)
    raise ValueError(f"bending must be one of {BENDING_MEASURES}, got {bending!r}")


def curvature_binormal(x: np.ndarray, closed: bool) -> np.ndarray:
    """Curvature binormal kb at every joint, shape (..., n_joints, 3), dimensionless.

    x: vertex positions [m], shape (..., n_vertices, 3).
    """
    return JointGeometry(*joint_pairs(edges(x, closed), closed)).kb


def turning_angles(x: np.ndarray, closed: bool) -> np.ndarray:
    """Turning angle at every joint [rad], shape (..., n_joints).

    x: vertex positions [m], shape (..., n_vertices, 3).
    """
    return JointGeometry(*joint_pairs(edges(x, closed), closed)).turning_angle


def writhe(x: np.ndarray) -> float:
    """Writhe Wr of a closed polygon (dimensionless), shape (n_vertices, 3) [m].

    The Gauss double integral summed exactly over pairs of edges: each pair
    contributes the signed solid angle it subtends over 4 pi (Klenin and
    Langowski, Biopolymers 2000). With the twist Tw (in turns) of a ring,
    Tw + Wr is the linking number, which is conserved while the ring does not
    pass through itself (Calugareanu).
    """
    p1 = x
    p2 = np.roll(x, -1, axis=0)
    n = len(x)
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # the last edge is adjacent to the first
    i, j = i[keep], j[keep]
    a, b, c, d = p1[i], p2[i], p1[j], p2[j]
    r13, r14, r23, r24 = c - a, d - a, c - b, d - b

    def unit_cross(u, v):
        w = np.cross(u, v)
        return w / np.maximum(norm(w), 1e-300)[:, None]

    n1, n2 = unit_cross(r13, r14), unit_cross(r14, r24)
    n3, n4 = unit_cross(r24, r23), unit_cross(r23, r13)
    dot = lambda u, v: np.clip(np.einsum("ij,ij->i", u, v), -1.0, 1.0)  # noqa: E731
    omega = np.arcsin(dot(n1, n2)) + np.arcsin(dot(n2, n3)) + np.arcsin(dot(n3, n4)) + np.arcsin(dot(n4, n1))
    sign = np.sign(np.einsum("ij,ij->i", np.cross(d - c, b - a), r13))
    return float(np.sum(omega * sign) / (2.0 * np.pi))


def arc_length_to(x: np.ndarray, p: np.ndarray) -> float:
    """Arc length [m] along the polyline x (n, 3) [m] of its point closest to p (3,) [m]:
    where along a rod something holds it (a gripper's pads, examples/grasp.py)."""
    a, b = x[:-1], x[1:]
    e = b - a
    u = np.clip(np.einsum("ij,ij->i", p - a, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
    k = int(np.argmin(np.linalg.norm(a + u[:, None] * e - p, axis=1)))
    lengths = np.linalg.norm(e, axis=1)
    return float(np.sum(lengths[:k]) + u[k] * lengths[k])
