"""Elastic energies of a discrete rod with exact gradients and Hessians.

Bergou et al. 2008 (eqs. 3 to 6) and Bergou et al. 2010. Each term is a pure
function of a :class:`Configuration` (the current centerline and frames) and
of arrays of rest quantities and stiffnesses; it returns a :class:`Derivatives`
holding the energy, its gradient and, on request, its Hessian per stencil
(:class:`derods.stencil.Hessian`).

What "exact" means where reference frames are involved. The reference frame
of edge j is the time-parallel transport of a given frame (u^j, t^j) to the
edge's current tangent, so every energy is an ordinary function E(x, theta)
of the vertex positions and twist angles for fixed (u, t). Gradients and
Hessians are its derivatives at the configuration where the frames are
adapted (current tangents equal t), which is where the simulation evaluates
them. The finite-difference tests in tests/test_energy.py check exactly this
function. Its x-x Hessian is the symmetric part of the Jacobian of the
adapted-frame gradient: transport holonomy adds only an antisymmetric
(t x) term per edge to that Jacobian.

Energies (l_k the vertex length of joint k, see :func:`derods.geometry.voronoi_len`):

* stretch: sum_j (k_s / 2) |ebar^j| (|e^j| / |ebar^j| - 1)^2, k_s = E A [N];
* isotropic bend (straight rest shape): sum_k alpha |kb_k|^2 / l_k, alpha = E I [N m^2];
* material bend (anisotropic and/or curved rest shape): sum_k 1/(2 l_k)
  sum_{s in prev, next} sum_c B_c (omega_k^s_c - omegabar_k^s_c)^2, omega the
  material curvatures of :func:`derods.frames.material_curvatures`;
* twist: sum_k beta (m_k - mbar_k)^2 / l_k, m_k = theta^next - theta^prev +
  ref_twist_k (+ a seam offset on closed rods), beta = G J [N m^2].

The bending terms take a measure of bending (``bending``, see
:data:`derods.geometry.BENDING_MEASURES`): Bergou's kb, |kb| = 2 tan(phi / 2) (the
default), or the turning angle kb_angle = phi kb / |kb| (:class:`derods.geometry.TurningAngle`),
which enters every formula above in kb's place, its Jacobians and second derivatives too.
The twist's reference twist keeps Bergou's kb: its gradient is a fact of parallel transport.

Every term also offers a positive semi-definite Hessian (``psd=True``), its
Gauss-Newton part (the squared Jacobian of the strain, plus the stretch term
only while an edge is stretched), for implicit time stepping.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import frames as _frames
from .geometry import JointGeometry, curvature, edges, joint_pairs, norm
from .stencil import Hessian, add_optional, scatter_edge_x, scatter_joint_theta, scatter_joint_x


class Configuration:
    """A rod's current shape, with the per-step geometry every term shares.

    x: vertex positions [m], shape (..., n_vertices, 3).
    closed: whether the last vertex connects back to the first.
    u: reference directors of the edges (adapted: perpendicular to the current
       tangents), shape (..., n_edges, 3); needed only by frame-dependent terms.
    theta: twist angles of the material frames [rad], shape (..., n_edges).
    """

    def __init__(self, x: np.ndarray, closed: bool, u: np.ndarray | None = None,
                 theta: np.ndarray | None = None):
        self.x = x
        self.closed = closed
        self.e = edges(x, closed)
        self.edge_len = norm(self.e)
        self.t = self.e / self.edge_len[..., None]
        self.joint = JointGeometry(*joint_pairs(self.e, closed))
        self.u = u
        self.theta = theta
        self._m = None

    @property
    def n_vertices(self) -> int:
        return self.x.shape[-2]

    @property
    def n_edges(self) -> int:
        return self.e.shape[-2]

    def material_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(m1, m2), each (..., n_edges, 3); requires ``u`` and ``theta``."""
        if self._m is None:
            if self.u is None or self.theta is None:
                raise ValueError("this energy term needs reference frames u and twist angles theta")
            self._m = _frames.material_frames(self.u, self.t, self.theta)
        return self._m

    def reference_twist(self) -> np.ndarray:
        """Reference twist of every joint [rad], shape (..., n_joints); requires ``u``."""
        if self.u is None:
            raise ValueError("the twist term needs reference frames u")
        return _frames.reference_twist(self.u, self.t, self.closed)


@dataclass
class Derivatives:
    """Energy [J], gradient w.r.t. x [N] (shape (..., n_vertices, 3)), gradient
    w.r.t. theta [N m] (shape (..., n_edges), or None when the term does not
    depend on theta), and the Hessian (None unless asked for)."""

    energy: np.ndarray
    grad_x: np.ndarray | None = None
    grad_theta: np.ndarray | None = None
    hessian: Hessian | None = None

    def __add__(self, other: "Derivatives") -> "Derivatives":
        add = add_optional
        return Derivatives(
            self.energy + other.energy,
            add(self.grad_x, other.grad_x),
            add(self.grad_theta, other.grad_theta),
            add(self.hessian, other.hessian),
        )


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., :, None] * b[..., None, :]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _sym(h: np.ndarray) -> np.ndarray:
    return 0.5 * (h + np.swapaxes(h, -1, -2))


def _jt(j_ab: np.ndarray, w: np.ndarray) -> np.ndarray:
    """J^T w for J (..., 3, 6) and w (..., 3) -> (..., 6)."""
    return np.einsum("...ki,...k->...i", j_ab, w)


# Edge-space (a = e_prev, b = e_next) to vertex-space (x_prev, x_joint, x_next).
# a = x_joint - x_prev, b = x_next - x_joint, so d/dx = T^T d/d(a, b).
_T = np.zeros((6, 9))
_T[0:3, 0:3], _T[0:3, 3:6] = -np.eye(3), np.eye(3)
_T[3:6, 3:6], _T[3:6, 6:9] = -np.eye(3), np.eye(3)


def _ab_to_x_vec(g: np.ndarray) -> np.ndarray:
    """(..., 6) gradient over (a, b) -> (..., 3, 3) over the three stencil vertices."""
    ga, gb = g[..., :3], g[..., 3:]
    return np.stack([-ga, ga - gb, gb], axis=-2)


def _ab_to_x_mat(h: np.ndarray) -> np.ndarray:
    """(..., 6, 6) Hessian over (a, b) -> (..., 9, 9) over the stencil vertices."""
    return np.einsum("ai,...ab,bj->...ij", _T, h, _T, optimize=True)


def _ab_to_x_cols(h: np.ndarray) -> np.ndarray:
    """(..., 6, c) mixed block over (a, b) rows -> (..., 9, c) over stencil vertices."""
    return np.einsum("ai,...ac->...ic", _T, h)


def stretch(cfg: Configuration, ks, rest_len: np.ndarray, order: int = 1,
            psd: bool = False) -> Derivatives:
    """Stretching energy sum_j (ks/2) |ebar^j| (|e^j|/|ebar^j| - 1)^2.

    ks: stretching stiffness E A [N], scalar or shape (..., n_edges).
    rest_len: rest edge lengths [m], shape (..., n_edges).
    order: 0 energy, 1 adds the gradient, 2 adds the Hessian.
    psd: drop the geometric (transverse) term of compressed edges.
    """
    strain = cfg.edge_len / rest_len - 1.0
    energy = 0.5 * np.sum(ks * rest_len * strain**2, axis=-1)
    if order < 1:
        return Derivatives(energy)
    tension = ks * strain  # [N]
    g = tension[..., None] * cfg.t
    grad_x = scatter_edge_x(np.stack([-g, g], axis=-2), cfg.n_vertices, cfg.closed)
    if order < 2:
        return Derivatives(energy, grad_x)
    tt = _outer(cfg.t, cfg.t)
    geo = np.maximum(tension, 0.0) if psd else tension
    h = (ks / rest_len)[..., None, None] * tt + (geo / cfg.edge_len)[..., None, None] * (np.eye(3) - tt)
    block = np.empty(h.shape[:-2] + (6, 6))
    block[..., :3, :3] = h
    block[..., 3:, 3:] = h
    block[..., :3, 3:] = -h
    block[..., 3:, :3] = -h
    return Derivatives(energy, grad_x, None, Hessian(cfg.n_vertices, cfg.closed, edge_xx=block))


def bend_isotropic(cfg: Configuration, alpha, vlen: np.ndarray, order: int = 1,
                   psd: bool = False, bending: str = "tan") -> Derivatives:
    """Isotropic bending energy of a naturally straight rod, sum_k alpha |kb_k|^2 / l_k.

    Needs no frames: with no rest curvature the material frame drops out.
    alpha: bending stiffness E I [N m^2], scalar or shape (..., n_joints).
    vlen: vertex lengths l_k [m], shape (..., n_joints).
    bending: "tan" (kb, Bergou et al. 2008) or "angle" (|kb_angle| = phi, the turning angle).
    """
    jg = curvature(cfg.joint, bending)
    kb = jg.kb
    c = alpha / vlen  # [N m]
    energy = np.sum(c * _dot(kb, kb), axis=-1)
    if order < 1:
        return Derivatives(energy)
    j_ab = jg.jacobian_ab()
    g_ab = (2.0 * c)[..., None] * _jt(j_ab, kb)
    grad_x = scatter_joint_x(_ab_to_x_vec(g_ab), cfg.n_vertices, cfg.closed)
    if order < 2:
        return Derivatives(energy, grad_x)
    h = np.einsum("...ki,...kj->...ij", j_ab, j_ab)
    if not psd:
        h = h + jg.kb_hessian_dot(kb)
    h = (2.0 * c)[..., None, None] * h
    return Derivatives(energy, grad_x, None, Hessian(cfg.n_vertices, cfg.closed, joint_xx=_ab_to_x_mat(h)))


def bend_material(cfg: Configuration, stiffness: np.ndarray, vlen: np.ndarray,
                  rest_curvature: np.ndarray | None = None, order: int = 1,
                  psd: bool = False, bending: str = "tan") -> Derivatives:
    """Bending energy in material curvatures (anisotropic and/or naturally curved rods).

    E = sum_k 1/(2 l_k) sum_{s = prev, next} sum_{c = 1, 2}
        B_c (omega_k^s_c - omegabar_k^s_c)^2   (Bergou et al. 2008, eq. 5)

    stiffness: principal bending stiffnesses (B1, B2) = (E I1, E I2) [N m^2],
        shape (2,) for a uniform rod, or anything that broadcasts to
        (..., n_joints, 2, 2) (per joint and side; (n_rods, 1, 1, 2) for a batch).
        B1 weighs omega_1 = kb . m2, the bending about m1 (in the plane of t and m2).
    vlen: vertex lengths l_k [m], shape (..., n_joints).
    rest_curvature: omegabar, shape (..., n_joints, 2, 2), or None for straight (taken
        with the same measure: :attr:`derods.Rod.rest_curvature` is).
    bending: "tan" (kb, Bergou et al. 2008) or "angle" (|kb_angle| = phi, the turning angle).
    Requires ``cfg.u`` and ``cfg.theta``.
    """
    jg = curvature(cfg.joint, bending)
    kb = jg.kb
    m1, m2 = cfg.material_frames()
    m1s = np.stack(joint_pairs(m1, cfg.closed), axis=-2)  # (..., nj, 2, 3)
    m2s = np.stack(joint_pairs(m2, cfg.closed), axis=-2)
    # n[..., s, c, :]: omega_sc = kb . n_sc; n_s0 = m2^s, n_s1 = -m1^s.
    n = np.stack([m2s, -m1s], axis=-2)  # (..., nj, 2, 2, 3)
    omega = np.einsum("...i,...sci->...sc", kb, n)
    # (B1, B2) of shape (2,) broadcasts over joints and sides on its own.
    b = np.broadcast_to(np.asarray(stiffness, dtype=float), omega.shape)
    b_over_l = b / vlen[..., None, None]
    dw = omega if rest_curvature is None else omega - rest_curvature
    energy = 0.5 * np.sum(b_over_l * dw**2, axis=(-3, -2, -1))
    if order < 1:
        return Derivatives(energy)
    r = b_over_l * dw  # dE/domega
    # rho_sc = d omega_sc / d theta^s: rho_s0 = omega_s1, rho_s1 = -omega_s0.
    rho = np.stack([omega[..., 1], -omega[..., 0]], axis=-1)
    j_ab = jg.jacobian_ab()
    w_g = np.einsum("...sc,...sci->...i", r, n)
    g_ab = _jt(j_ab, w_g)
    grad_x = scatter_joint_x(_ab_to_x_vec(g_ab), cfg.n_vertices, cfg.closed)
    g_t = np.sum(r * rho, axis=-1)  # (..., nj, 2)
    grad_theta = scatter_joint_theta(g_t, cfg.n_edges, cfg.closed)
    if order < 2:
        return Derivatives(energy, grad_x, grad_theta)
    jn = np.einsum("...ki,...sck->...sci", j_ab, n)  # d omega / d(a, b): (..., nj, 2, 2, 6)
    h_ab = np.einsum("...sc,...sci,...scj->...ij", b_over_l, jn, jn)
    shape_t = omega.shape[:-2] + (2, 2)
    h_tt = np.zeros(shape_t)
    h_tt[..., 0, 0] = np.sum(b_over_l[..., 0, :] * rho[..., 0, :] ** 2, axis=-1)
    h_tt[..., 1, 1] = np.sum(b_over_l[..., 1, :] * rho[..., 1, :] ** 2, axis=-1)
    # d(omega)/d(a,b) times d(omega)/d(theta): the Gauss-Newton mixed block.
    h_xt_ab = np.einsum("...sc,...sci,...sc->...is", b_over_l, jn, rho)  # (..., nj, 6, 2)
    if not psd:
        h_ab = h_ab + jg.kb_hessian_dot(w_g)
        # Transport of the material frame with its edge: d n / d e^s = -t^s n^T / |e^s|,
        # and J^T t^s = -kb / |e^s| on the rows of e^s (kb . t^s = 0 at every shape, for
        # either measure: the derivative of that identity).
        lens = np.stack([jg.la, jg.lb], axis=-1)  # (..., nj, 2)
        ws = np.einsum("...sc,...sci->...si", r, n)  # (..., nj, 2, 3)
        f = kb[..., None, :, None] * ws[..., :, None, :] / (lens**2)[..., :, None, None]
        frame = np.zeros(h_ab.shape)
        frame[..., :3, :3] = f[..., 0, :, :]
        frame[..., 3:, 3:] = f[..., 1, :, :]
        h_ab = _sym(h_ab + frame)
        # d n_sc / d theta^s: n_s0 -> n_s1, n_s1 -> -n_s0.
        dn = np.stack([n[..., 1, :], -n[..., 0, :]], axis=-2)
        h_xt_ab = h_xt_ab + np.einsum("...ki,...sck,...sc->...is", j_ab, dn, r)
        h_tt[..., 0, 0] -= np.sum(r[..., 0, :] * omega[..., 0, :], axis=-1)
        h_tt[..., 1, 1] -= np.sum(r[..., 1, :] * omega[..., 1, :], axis=-1)
    hess = Hessian(cfg.n_vertices, cfg.closed, joint_xx=_ab_to_x_mat(h_ab),
                   joint_xt=_ab_to_x_cols(h_xt_ab), joint_tt=h_tt)
    return Derivatives(energy, grad_x, grad_theta, hess)


def reference_twist_gradient(jg: JointGeometry) -> np.ndarray:
    """d(ref_twist_k) / d(e_prev, e_next) = (kb / (2 |e_prev|), kb / (2 |e_next|)) [1/m].

    Bergou et al. 2010, section 6. Shape (..., n_joints, 6).
    """
    kb = jg.kb
    return np.concatenate([kb / (2.0 * jg.la)[..., None], kb / (2.0 * jg.lb)[..., None]], axis=-1)


def reference_twist_hessian(jg: JointGeometry) -> np.ndarray:
    """Hessian of the reference twist over (e_prev, e_next) [1/m^2], shape (..., n_joints, 6, 6).

    The symmetric part of the Jacobian of :func:`reference_twist_gradient`.
    """
    ja, jb = jg.jacobians()
    la, lb = jg.la[..., None, None], jg.lb[..., None, None]
    kb = jg.kb
    h = np.empty(kb.shape[:-1] + (6, 6))
    h[..., :3, :3] = ja / (2 * la) - _outer(kb, jg.ta) / (2 * la**2)
    h[..., :3, 3:] = jb / (2 * la)
    h[..., 3:, :3] = ja / (2 * lb)
    h[..., 3:, 3:] = jb / (2 * lb) - _outer(kb, jg.tb) / (2 * lb**2)
    return _sym(h)


def twist(cfg: Configuration, beta, vlen: np.ndarray, rest_twist=0.0, twist_offset=0.0,
          order: int = 1, psd: bool = False) -> Derivatives:
    """Twisting energy sum_k beta (m_k - mbar_k)^2 / l_k (Bergou et al. 2008, eq. 6).

    m_k = theta^next - theta^prev + ref_twist_k + twist_offset_k.
    beta: twisting stiffness G J [N m^2], scalar or shape (..., n_joints).
    vlen: vertex lengths l_k [m], shape (..., n_joints).
    rest_twist: mbar [rad], scalar or shape (..., n_joints).
    twist_offset: added to m [rad]; a closed rod with imposed total twist Theta
        has Theta at its seam joint 0 (see :mod:`derods.twist`).
    Requires ``cfg.u`` and ``cfg.theta``.
    """
    jg = cfg.joint
    th_a, th_b = joint_pairs(cfg.theta[..., None], cfg.closed)
    m = th_b[..., 0] - th_a[..., 0] + cfg.reference_twist() + twist_offset
    c = beta / vlen
    dm = m - rest_twist
    energy = np.sum(c * dm**2, axis=-1)
    if order < 1:
        return Derivatives(energy)
    s = 2.0 * c * dm  # dE/dm [N m]
    g_r = reference_twist_gradient(jg)
    grad_x = scatter_joint_x(_ab_to_x_vec(s[..., None] * g_r), cfg.n_vertices, cfg.closed)
    grad_theta = scatter_joint_theta(np.stack([-s, s], axis=-1), cfg.n_edges, cfg.closed)
    if order < 2:
        return Derivatives(energy, grad_x, grad_theta)
    cc = (2.0 * c)[..., None, None]
    h_ab = cc * _outer(g_r, g_r)
    if not psd:
        h_ab = h_ab + s[..., None, None] * reference_twist_hessian(jg)
    dth = np.array([-1.0, 1.0])
    h_xt = cc * (_ab_to_x_vec(g_r).reshape(g_r.shape[:-1] + (9,))[..., :, None] * dth)
    h_tt = cc * np.outer(dth, dth)
    hess = Hessian(cfg.n_vertices, cfg.closed, joint_xx=_ab_to_x_mat(h_ab), joint_xt=h_xt, joint_tt=h_tt)
    return Derivatives(energy, grad_x, grad_theta, hess)
