"""A discrete elastic rod: frozen parameters, a separate state, and its energy.

:class:`Rod` holds the rest shape and everything derived from it that stays fixed
during a run; the physical constants are a :class:`~derods.material.Material`
(:mod:`derods.material`), what changes every step (positions, reference frames, twist
angles) a :class:`~derods.rod_state.RodState` (:mod:`derods.rod_state`). The rod
decides once, from its parameters, which energy terms it needs
(:attr:`Rod.active_terms`) and evaluates only those.

A :class:`Rod` may describe many rods of equal vertex count at once: give
``rest_x`` leading batch dimensions, e.g. shape (n_rods, n_vertices, 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import energy, frames, geometry, stencil, twist, validation
from .energy import Configuration, Derivatives
from .material import INEXTENSIBLE_MODULUS, Material
from .rod_state import RodState, StepTerms
from .twist import TwistBoundary

#: The sharpest turn [rad] a rod may take at a vertex: two edges folded back onto each
#: other (pi) have an infinite discrete curvature.
MAX_TURN = math.radians(179.0)


def check_turns(name: str, x: np.ndarray, closed: bool) -> None:
    """Refuse positions whose edges fold back onto each other (a turn above MAX_TURN at a
    vertex), naming the vertex and what to do."""
    # atan2(|a x b|, a . b): exact also at a full fold, where kb (and turning_angles) is 0 / 0.
    ta, tb = geometry.joint_pairs(frames.tangents(x, closed), closed)
    turn = np.arctan2(geometry.norm(np.cross(ta, tb)), np.einsum("...i,...i->...", ta, tb))
    if turn.size and np.max(turn) > MAX_TURN:
        idx = np.unravel_index(int(np.argmax(turn)), turn.shape)
        k = int(idx[-1]) if closed else int(idx[-1]) + 1
        raise validation.InvalidInputError(
            f"{name} turns by {math.degrees(float(turn[idx])):.1f} degrees at vertex {k}: its edges fold back onto each "
            f"other, where a discrete rod's curvature is infinite; round the fold over several edges (at most "
            f"{math.degrees(MAX_TURN):.0f} degrees per vertex)")


@dataclass(frozen=True)
class Rod:
    """Rest shape and material of a rod (or of a batch of rods of equal size).

    rest_x: rest vertex positions [m], shape (..., n_vertices, 3).
    material: the :class:`Material`.
    closed: whether the rod is a ring.
    boundary: how the material frame is held (:class:`derods.twist.TwistBoundary`).
    rest_twist: extra natural twist per joint [rad] on top of the rest shape's own.
    stretch_stiffness: k_s [N]. None (default) makes the rod practically
        inextensible: k_s = A max(E, INEXTENSIBLE_MODULUS), which the implicit
        step of the MuJoCo coupling keeps stable at any time step. Pass E A
        (``material.stretch_stiffness``) for a physically extensible rod.
    u0: first reference director of the rest shape, shape (3,) or None.
    natural_curvature: True (default) if ``rest_x`` is the stress-free shape;
        False for a naturally straight rod that merely starts in the shape of
        ``rest_x`` (a straight rod closed into a ring, as in Michell's test):
        then ``rest_x`` sets only the rest edge lengths.
    bending: how a joint's bending is measured, the same in every term it enters (bending
        energy, forces, the implicit step's Hessian, the natural curvature of ``rest_x``):

        * "tan" (default): Bergou et al. 2008's curvature binormal kb, |kb| = 2 tan(phi / 2)
          for a turning angle phi at the joint; the paper's discretization.
        * "angle": the turning angle itself, kb_angle = phi kb / |kb|
          (:class:`derods.geometry.TurningAngle`), as MuJoCo's cable measures it. A rod
          under a constant moment M then turns by exactly M h / alpha per joint (h the
          edge length), so a
          sampled arc of constant curvature is an equilibrium without discretization
          error (an end couple 2 pi alpha / L closes a clamped rod into a regular polygon
          exactly, where "tan" falls short by about phi^2 / 3), and the energy stays
          finite as a joint folds back (phi -> pi), where tan(phi / 2) has a pole.

        They differ by O(phi^2) per joint and converge to the same continuum rod; pick
        "angle" to match MuJoCo's cable or closed forms of constant curvature, "tan" (the
        default, whose results are unchanged by this option) to follow the paper.
    """

    rest_x: np.ndarray
    material: Material
    closed: bool = False
    boundary: TwistBoundary = TwistBoundary()
    rest_twist: float | np.ndarray = 0.0
    stretch_stiffness: float | None = None
    u0: np.ndarray | None = None
    natural_curvature: bool = True
    bending: str = "tan"
    rest_len: np.ndarray = field(init=False, repr=False)
    vlen: np.ndarray = field(init=False, repr=False)
    rest_u: np.ndarray = field(init=False, repr=False)
    rest_curvature: np.ndarray | None = field(init=False, repr=False)
    mbar: np.ndarray = field(init=False, repr=False)
    active_terms: tuple[str, ...] = field(init=False)

    def __post_init__(self):
        x = validation.rod_fields(self)
        check_turns("rest_x", x, self.closed)
        rest_len = geometry.norm(geometry.edges(x, self.closed))
        u = frames.bishop_frames(x, self.closed, self.u0)
        cfg = Configuration(x, self.closed, u, np.zeros(rest_len.shape))
        # The rest shape's own reference twist (the holonomy at a ring's seam)
        # is natural twist: a rod at rest carries no twisting moment.
        mbar = np.broadcast_to(np.asarray(self.rest_twist, dtype=float), cfg.joint.la.shape)
        straight = not self.natural_curvature or bool(np.all(geometry.norm(cfg.joint.kb) < 1e-9))
        if self.natural_curvature:
            mbar = mbar + cfg.reference_twist()
        curvature = None
        if not straight:
            m1, m2 = cfg.material_frames()
            kb = geometry.curvature(cfg.joint, self.bending).kb
            curvature = frames.material_curvatures(kb, m1, m2, self.closed)
        terms = ["stretch"]
        frame_bend = (not straight) or (not self.material.isotropic)
        terms.append("bend_material" if frame_bend else "bend_isotropic")
        if frame_bend or self.boundary.kind != "free":
            terms.append("twist")
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("rest_x", x)
        set_("rest_len", rest_len)
        set_("vlen", geometry.voronoi_len(rest_len, self.closed))
        set_("rest_u", u)
        set_("rest_curvature", curvature)
        set_("mbar", mbar)
        set_("active_terms", tuple(terms))

    # -- sizes ---------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        return self.rest_x.shape[-2]

    @property
    def n_edges(self) -> int:
        return geometry.n_edges(self.n_vertices, self.closed)

    @property
    def length(self) -> np.ndarray:
        """Rest length [m], shape (...)."""
        return np.sum(self.rest_len, axis=-1)

    @property
    def ks(self) -> float:
        """Stretching stiffness k_s [N]."""
        if self.stretch_stiffness is not None:
            return self.stretch_stiffness
        return self.material.area * max(self.material.young, INEXTENSIBLE_MODULUS)

    @property
    def vertex_mass(self) -> np.ndarray:
        """Lumped masses [kg], shape (..., n_vertices): half of each adjacent edge's mass."""
        me = self.material.line_density * self.rest_len
        if self.closed:
            return 0.5 * (me + np.roll(me, 1, axis=-1))
        m = np.zeros(me.shape[:-1] + (self.n_vertices,))
        m[..., :-1] += 0.5 * me
        m[..., 1:] += 0.5 * me
        return m

    # -- state ---------------------------------------------------------------
    def rest_state(self) -> RodState:
        """The rod at rest: rest positions, Bishop frames, zero twist angles."""
        t = frames.tangents(self.rest_x, self.closed)
        return RodState(self.rest_x.copy(), self.rest_u.copy(), t, np.zeros(t.shape[:-1]))

    def advance(self, state: RodState, x: np.ndarray) -> RodState:
        """New state at positions ``x`` [m], shape (..., n_vertices, 3).

        Transports the reference frames in time to the new tangents (Bergou et
        al. 2010) and solves the quasistatic twist (Bergou et al. 2008, 4.4).
        """
        validation.rod_state(self, state)
        validation.rod_positions(self, x)
        t = frames.tangents(x, self.closed)
        u = frames.time_parallel_transport(state.u, state.t, t)
        new = RodState(x, u, t, state.theta)
        if "twist" in self.active_terms:
            new.theta = self.solve_twist(new)
        return new

    def solve_twist(self, state: RodState, boundary: TwistBoundary | None = None) -> np.ndarray:
        """Twist angles [rad] that make the energy stationary, shape (..., n_edges).

        boundary: this step's boundary (moving clamps); default ``self.boundary``.
        """
        validation.rod_state(self, state)
        if boundary is not None:
            validation.instance("boundary", boundary, TwistBoundary, "pass derods.TwistBoundary(...)")
        bd = self.boundary if boundary is None else boundary
        if "bend_material" not in self.active_terms:
            ref = frames.reference_twist(state.u, state.t, self.closed)
            theta, _ = twist.solve_isotropic(ref, self.vlen, self.material.beta, bd, self.mbar)
            return theta
        if state.x.ndim > 2:
            raise validation.InvalidInputError("the Newton twist solve takes one rod at a time; loop over the batch")

        def theta_energy(theta, order):
            cfg = Configuration(state.x, self.closed, state.u, theta)
            return self._terms(cfg, order, psd=False, names=("bend_material", "twist"))

        theta0 = np.array(state.theta, dtype=float)
        if bd.theta_first is not None:
            theta0[0] = bd.theta_first
        if bd.theta_last is not None:
            theta0[-1] = bd.theta_last
        return twist.solve_newton(theta_energy, theta0, self.closed, bd)

    # -- energy --------------------------------------------------------------
    def _terms(self, cfg: Configuration, order: int, psd: bool, names) -> Derivatives:
        mat = self.material
        out = None
        for name in names:
            if name == "stretch":
                d = energy.stretch(cfg, self.ks, self.rest_len, order, psd)
            elif name == "bend_isotropic":
                d = energy.bend_isotropic(cfg, mat.alpha, self.vlen, order, psd, self.bending)
            elif name == "bend_material":
                d = energy.bend_material(cfg, np.array(mat.bend_stiffness), self.vlen,
                                         self.rest_curvature, order, psd, self.bending)
            elif name == "twist":
                off = self.boundary.seam_offset(self.vlen.shape[-1])
                d = energy.twist(cfg, mat.beta, self.vlen, self.mbar, off, order, psd)
            else:  # pragma: no cover - names come from active_terms
                raise KeyError(name)
            out = d if out is None else out + d
        return out

    def derivatives(self, state: RodState, order: int = 1, psd: bool = False,
                    terms: tuple[str, ...] | None = None) -> Derivatives:
        """Energy [J], gradients and (order=2) Hessian of the active terms at ``state``.

        ``state`` must have adapted frames (from :meth:`rest_state` or
        :meth:`advance`). psd: positive semi-definite Hessian for implicit steps.
        terms: a subset of :attr:`active_terms` (default: all of them).
        """
        validation.rod_state(self, state)
        if validation.integer("order", order) not in (0, 1, 2):
            validation.refuse("order", "0 (energy), 1 (and gradients) or 2 (and Hessian)", order)
        validation.boolean("psd", psd)
        names = self.active_terms if terms is None else terms
        if isinstance(names, str):
            validation.refuse("terms", f"a tuple of term names from {self.active_terms}", names,
                              f"pass ({names!r},)", validation.InvalidTypeError)
        unknown = set(names) - set(self.active_terms)
        if unknown:
            raise validation.InvalidInputError(f"terms {sorted(unknown)} are not active for this rod; active: "
                                               f"{self.active_terms}")
        cfg = Configuration(state.x, self.closed, state.u, state.theta)
        return self._terms(cfg, order, psd, names)

    @property
    def has_closed_form_twist(self) -> bool:
        """True for an isotropic, naturally straight rod: its quasistatic twist is solved in
        closed form and enters as a reduced, rank-one term (others need Newton's method)."""
        return "bend_material" not in self.active_terms

    def step_terms(self, state: RodState, x: np.ndarray, use_kernel: bool | None = None,
                   boundary: TwistBoundary | None = None) -> StepTerms:
        """Advance to positions ``x`` and evaluate what an implicit step needs.

        state: the previous state (its frames are transported to ``x``).
        x: new vertex positions [m], shape (..., n_vertices, 3).
        use_kernel: the compiled kernel (True, the default) or the numpy path it is tested
            against (False). Both give the same numbers (to round-off; for anisotropic or
            naturally curved rods, to the Newton twist solve's tolerance).
        boundary: this step's twist boundary, when clamps move (default: ``self.boundary``);
            it must be of the same kind.
        """
        validation.rod_state(self, state)
        validation.rod_positions(self, x)
        if boundary is not None:
            validation.instance("boundary", boundary, TwistBoundary, "pass derods.TwistBoundary(...)")
        if boundary is not None and boundary.kind != self.boundary.kind:
            raise validation.InvalidInputError(f"boundary kind {boundary.kind!r} differs from the rod's "
                                               f"{self.boundary.kind!r}")
        bd = self.boundary if boundary is None else boundary
        if use_kernel is None or use_kernel:
            return self._step_terms_kernel(state, x, bd)
        if "bend_material" in self.active_terms:
            return self._step_terms_material(state, x, bd)
        t = frames.tangents(x, self.closed)
        u = frames.time_parallel_transport(state.u, state.t, t)
        cfg = Configuration(x, self.closed, u, state.theta)
        names = tuple(n for n in self.active_terms if n != "twist")
        d = self._terms(cfg, 2, True, names)
        grad, e = d.grad_x, d.energy
        if "twist" in self.active_terms:
            red = twist.reduce_isotropic(cfg, self.vlen, self.material.beta, bd, self.mbar)
            grad = grad + red.grad_x
            e = e + red.energy
        else:
            red = self._no_twist(np.broadcast_to(state.theta, t.shape[:-1]))
        return StepTerms(RodState(x, u, t, red.theta), e, grad, self._band(d.hessian), red,
                         self._clamp_moments(red.lam, bd, t.shape[:-1]))

    def _no_twist(self, theta: np.ndarray) -> twist.ReducedTwist:
        """A zero reduced twist term at angles ``theta`` (shape (..., n_edges))."""
        batch = theta.shape[:-1]
        zero = np.zeros(batch)
        return twist.ReducedTwist(np.array(theta, dtype=float), zero, zero.copy(),
                                  np.zeros(batch + (self.n_vertices, 3)), zero.copy())

    def _clamp_moments(self, lam: np.ndarray, bd: TwistBoundary, shape: tuple) -> np.ndarray:
        """dE/dtheta at the closed-form twist solution, shape (..., n_edges): zero on free
        angles; -lam on the first and +lam on the last edge of a rod clamped at both ends."""
        g = np.zeros(shape)
        if bd.kind == "clamped":
            g[..., 0] = -lam
            g[..., -1] = lam
        return g

    def _band(self, hessian) -> np.ndarray:
        """The x-x Hessian's lower band: in vertex order for an open rod, in
        :func:`derods.stencil.ring_order` for a ring."""
        if not self.closed:
            return hessian.xx_banded()
        order = stencil.ring_order(self.n_vertices)
        batch = self.rest_x.shape[:-2]
        if not batch:
            return hessian.xx_banded_ordered(order, stencil.RING_BANDWIDTH)
        # One ring at a time (this is the numpy oracle of the compiled path).
        out = []
        blocks = {k: getattr(hessian, k) for k in ("edge_xx", "joint_xx", "joint_xt", "joint_tt")}
        for idx in np.ndindex(*batch):
            one = stencil.Hessian(hessian.n_vertices, True,
                                  **{k: (None if v is None else v[idx]) for k, v in blocks.items()})
            out.append(one.xx_banded_ordered(order, stencil.RING_BANDWIDTH))
        return np.reshape(out, batch + out[0].shape)

    def _step_terms_material(self, state: RodState, x: np.ndarray, bd: TwistBoundary) -> StepTerms:
        """step_terms for anisotropic or naturally curved rods: Newton twist solve, then
        every term at the solved theta. The Hessian is the x-x block at fixed theta, which
        overestimates the stiffness that a relaxing material frame leaves (more damping
        in the implicit step, never less stability)."""
        t = frames.tangents(x, self.closed)
        u = frames.time_parallel_transport(state.u, state.t, t)
        theta = self.solve_twist(RodState(x, u, t, state.theta), bd)
        cfg = Configuration(x, self.closed, u, theta)
        d = self._terms(cfg, 2, True, self.active_terms)
        return StepTerms(RodState(x, u, t, theta), d.energy, d.grad_x, self._band(d.hessian),
                         self._no_twist(theta), d.grad_theta)

    def _kernel_plan(self, bd: TwistBoundary, n: int):
        """What the compiled step needs for n copies of this rod under boundary ``bd``: the
        :class:`derods.step.RodSet`, each vertex's place in its rod's band (a ring's in
        :func:`derods.stencil.ring_order`), one band per rod, no clamps on bodies, the
        band's rows (cached)."""
        from .step import EndBodies, RodSet

        cache = self.__dict__.setdefault("_kernel_plans", {})
        key = (bd, n)
        if key not in cache:
            nv = self.n_vertices
            rods = RodSet.of([self] if n == int(np.prod(self.rest_x.shape[:-2], dtype=int))
                             else [replace(self, rest_x=np.broadcast_to(self.rest_x, (n, nv, 3)).copy())], [bd])
            order = np.arange(nv) if not self.closed else np.argsort(stencil.ring_order(nv))
            place = np.tile(order, n).astype(np.int64)  # each rod in a band of its own
            rows = (stencil.RING_BANDWIDTH if self.closed else stencil.XX_BANDWIDTH) + 1
            cache[key] = (rods, place, np.arange(n, dtype=np.int64), EndBodies.none(n), np.zeros((1, 9)), rows)
        return cache[key]

    def _step_terms_kernel(self, state: RodState, x: np.ndarray, bd: TwistBoundary) -> StepTerms:
        from .step import Frames, Terms, evaluate

        batch = x.shape[:-2]
        nv, ne = self.n_vertices, self.n_edges
        n = int(np.prod(batch, dtype=int))

        def flat(a, *tail):
            # (batch..., *tail) -> (n * tail[0], *tail[1:]), a contiguous copy (the kernel
            # writes the frames in place).
            a = np.asarray(a, dtype=float)
            if a.shape != batch + tail:
                a = np.broadcast_to(a, batch + tail)
            return np.array(a.reshape((-1,) + tail[1:]), dtype=float)

        rods, place, band_of_rod, ends, xmat, rows = self._kernel_plan(bd, n)
        fr = Frames(flat(state.u, ne, 3), flat(state.t, ne, 3), flat(state.theta, ne), np.zeros((n, 2)))
        out = Terms.empty(n, n * nv, 0, rows)
        bands = np.empty((n, rows, 3 * nv))
        evaluate(rods, fr, flat(x, nv, 3), place, out, ends, xmat, np.inf, bands, band_of_rod)
        shape = lambda a, *tail: a.reshape(batch + tail)  # noqa: E731
        theta = shape(fr.theta, ne)
        if self.has_closed_form_twist and "twist" in self.active_terms:
            e_tw = np.divide(0.5 * out.lam**2, out.coef, out=np.zeros(n), where=out.coef > 0)
            red = twist.ReducedTwist(theta, shape(out.lam), shape(e_tw), shape(out.g_tw, nv, 3),
                                     shape(out.coef))
        else:
            red = self._no_twist(theta)
        if self.has_closed_form_twist:
            grad_theta = self._clamp_moments(red.lam, bd, batch + (ne,))
        else:
            # Zero on the free angles (solved); the held ends' moments from the kernel.
            grad_theta = np.zeros(batch + (ne,))
            grad_theta[..., 0] = shape(out.end_moment[:, 0])
            grad_theta[..., -1] = shape(out.end_moment[:, 1])
        return StepTerms(RodState(x, shape(fr.u, ne, 3), shape(fr.t, ne, 3), theta), shape(out.energy),
                         shape(out.grad, nv, 3), shape(bands, rows, 3 * nv), red, grad_theta)

    def energy(self, state: RodState) -> np.ndarray:
        """Total elastic energy [J], shape (...)."""
        return self.derivatives(state, order=0).energy

    def with_boundary(self, boundary: TwistBoundary) -> "Rod":
        """The same rod held differently."""
        validation.instance("boundary", boundary, TwistBoundary, "pass derods.TwistBoundary(...)")
        return replace(self, boundary=boundary)
