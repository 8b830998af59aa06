"""Static friction: a rod's resting contacts anchored where they started to stick.

MuJoCo's soft contact gives a pyramid edge row J_n +- mu J_t the reference acceleration
-B v - K imp dist: a position term along the normal only. Inside the friction cone both
edges of a pair are active and the friction force is 2 mu^2 D (-B v_t - a_t): a damper,
so a contact below the Coulomb threshold slides at v_t = f_t / (2 mu^2 D B) and never
recovers what it crept (measured: a rope on a 10 degree incline at mu = 0.3, 1.4-7.4 mm/s;
the pads of a robot's gripper let a cable fall in 0.5 s). And a pyramid's cross pair,
whose rows see the same penetration, takes part of the normal force that the pair along
the slide cannot use (on the incline, the friction along the slope topped out at
tan(10 deg) of the normal force against mu = 0.3).

Here each contact of a rod remembers where it began, a material point on each side (on a
rod: a point of the touching element, by its vertices; on a body: a point fixed in the
body), and its rows get the tangential position too: the slip s since then,

    pos_e = dist + sigma mu_j (s . t_j)      (row e = J_n + sigma mu_j J_tj, sigma = +-1),

so aref_e = -B v_e - K imp pos_e: MuJoCo's own spring, of the normal's time constant,
acting along the contact's tangents. A sticking contact holds its place (it moves only by
the spring's stretch, f_t / (2 mu^2 D K)), and the anchor's pull drives the cross pair's
rows out of the pyramid, so friction reaches mu f_n along the slide. A contact that slips
(its solved force all in one row of each pair: on the pyramid's boundary) is anchored
again where it is: kinetic friction as before. A contact is known from step to step by
its two sides (geom, or flex element / vertex); one that is gone is forgotten. Measured
(the incline, E 3e5 / 1e9 Pa, dt 1e-3): 7.4 / 1.4 mm/s of creep at 10 degrees became
0.001 / 0.000 mm/s, 15 degrees (0.89 of the friction angle) 0.0025 / 0.000; 20 degrees
(above it) slides as before.

A contact takes its anchor's spring only once it has lasted RESTING_STEPS steps without
sliding: anchored at once, the short contacts of a cable hopping as it is dragged over a
ledge's edge at dt = 1e-2 stuck and snapped, and it dipped deeper (the held-rods sweep:
11 of its 14 ledge cases at dt 1e-2 past the rod's radius, against 5 without anchors;
with the wait, every case of the sweep is judged as without anchors). Contacts sliding
faster than SLIDING_SPEED, or whose solved force lies on the pyramid's boundary, are
anchored again (kinetic friction as without anchors: a rope beyond its friction angle
slides at Coulomb's rate, within 0.5 %). MuJoCo's own solver has run by then (for rows
derods leaves to it, and in the modes whose contacts it solves): the anchors act in
derods' solve only. ``ContactParams(static_friction=True)`` turns them on; they are off
by default for their cost (~20-25 us per step with contacts, most of it fixed: reading
MuJoCo's contacts and boxing the new anchors; see ContactParams). With
pyramidal rows a sticking contact's friction still comes partly out of extra normal
force (the anchor loads one row of a pair, which pushes along n + mu t), and the pair
across the slide keeps normal force its friction cannot use: near the friction limit the
spring must stretch far (a capstan rope at 0.8 of its holding overhang rose 1.8 mm, at
0.95 slid off; a rope at 0.95 of its friction angle crept 10-18 mm/s).

Elliptic cones (MuJoCo's ``cone="elliptic"``, solved by derods as cones,
:mod:`derods._numba.cones`) have neither: a contact's frictional row j gets
aref -= K imp (s . t_j) / impratio, a spring as stiff as its normal row's (its weight is
the normal's times mu_j^2 / mu^2), so a contact carries friction f_t at a slip of
f_t / f_n times its penetration. A contact whose solved force lies on the cone (the cost's
middle zone: sliding) is not let go but dragged: its anchor moves to where the spring pulls
with the cone's limit, slip mu_1 times the penetration, and it keeps its age, so it holds
again the step the pull falls back inside (let go, it would slide on MuJoCo's damper for
RESTING_STEPS steps and pass the load on: the capstan crept 5.6 mm at 0.8). Measured: the
capstan holds at 0.8 and 0.95 (0, 0.34 mm) and slides beyond; the rope at 0.95 of its
friction angle, 0 mm/s; beyond it, Coulomb's rate within 1 %.
"""

from __future__ import annotations

from functools import cached_property

import mujoco
import numpy as np

from .._numba.friction import Anchors, FlexContacts, Kinds, Tables, anchor, no_anchors, reanchor_slipping
from .layout import element_bodies

#: A contact whose friction rows carry all but this share of its force slips.
SLIP_TOL = 1e-6
#: A contact whose sides moved apart faster than this [m/s] over the last step slides.
SLIDING_SPEED = 5e-2
#: Steps a contact must last before its anchor holds it (see the module docstring).
RESTING_STEPS = 10

__all__ = ["Anchors", "StaticFriction", "SLIP_TOL", "SLIDING_SPEED", "RESTING_STEPS"]


class StaticFriction:
    """The anchors of a world's rod contacts (see the module docstring); ``bool()`` is
    False for a model without 1D flexes, or with it turned off (``enabled``). Call
    :meth:`anchor` after MuJoCo's forward pass (and the reference corrections), before the
    rows are solved; :meth:`slipped` after the solve has written its row forces into
    ``efc_force``. ``state`` (:class:`derods._numba.friction.Anchors`) is what a step
    carries to the next."""

    def __init__(self, model: mujoco.MjModel):
        self.model = model
        self.enabled = bool(np.any(model.flex_dim == 1)) if model.nflex else False
        self.state = no_anchors()
        self._contacts = None
        self.kinds = Kinds(int(mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL),
                           int(mujoco.mjtConstraint.mjCNSTR_CONTACT_ELLIPTIC), float(model.opt.impratio))

    @cached_property
    def tables(self) -> Tables:
        """The model's tables the anchors read (:class:`derods._numba.friction.Tables`), made
        at the first anchored step: a world with static friction off never makes them."""
        m = self.model
        pad = lambda a: np.append(a, 0).astype(np.int64)  # noqa: E731
        return Tables(pad(m.geom_bodyid), pad(m.flex_elemadr), pad(m.flex_vertadr), element_bodies(m),
                      pad(m.flex_vertbodyid), int(m.ngeom), int(m.nflexelem))

    def __bool__(self) -> bool:
        return self.enabled

    def anchor(self, data: mujoco.MjData) -> None:
        """Carry the anchors over to this step's contacts (new ones anchored where they
        are) and add their slip to the pyramidal rows' reference accelerations
        (``data.efc_aref``, in place)."""
        d = data
        if d.ncon == 0:
            if len(self.state.keys):
                self.state = no_anchors()
            return
        con = d.contact
        contacts = FlexContacts(d.ncon, con.geom, con.flex, con.elem, con.vert, con.pos, con.frame, con.dim,
                                con.friction, con.efc_address)
        self.state = anchor(contacts, self.tables, self.state, d.efc_type, d.efc_KBIP, d.efc_aref, d.xpos, d.xmat,
                            self.kinds, SLIDING_SPEED * self.model.opt.timestep, RESTING_STEPS)
        self._contacts = contacts  # the step's contacts, for slipped

    def slipped(self, data: mujoco.MjData) -> None:
        """Anchor again where they are the contacts that slip: whose solved force lies on
        the pyramid's boundary, all of it in one row of each pair (no force spent in
        opposing rows, which would otherwise give way to more friction; a pair with one
        row active while its cross pair carries load is still inside, as on a slope below
        its friction angle)."""
        st = self.state
        if not len(st.keys):
            return
        con = self._contacts
        self.state = reanchor_slipping(st, con, data.efc_type, data.efc_force, data.efc_pos, data.xpos, data.xmat,
                                       self.kinds, SLIP_TOL)
