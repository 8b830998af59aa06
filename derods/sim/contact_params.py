"""How rods touch the scene: :class:`ContactParams`, the contact settings of a World.

One frozen record for all rods of a :class:`~derods.sim.world.World`, checked when made
(:func:`derods.validation.contact_params`); :func:`derods.sim.layout.add_to_spec` writes it
into the rods' flexes, and the contact stage reads its margin and holder contact.
"""

from __future__ import annotations

from dataclasses import dataclass

from .. import validation


@dataclass(frozen=True)
class ContactParams:
    """How rods touch the scene.

    friction: sliding friction coefficient. solref: MuJoCo (timeconst [s],
    dampratio); a time constant near 2 dt keeps fast impacts from sinking in.
    solimp: MuJoCo's impedance (dmin, dmax, width [m], midpoint, power); an
    impedance closer to 1 makes contacts harder and lets less friction creep.
    condim: contact dimensionality (1 frictionless, 3 sliding friction, 4 or 6
    adds torsional / rolling). self_collision: edges of a rod collide with its
    other edges, except those nearer along it than pi r (neighbours; for a rod thicker
    than half its edge, more: :func:`derods.sim.exclusion.self_reach`; the implicit and
    alpha modes, the others warn); off by default. rod_rod: rods touch one
    another (on by default; hair turns it off, its strands passing through each
    other; self_collision keeps it on). margin [m]: speculative contacts: rows
    are made for surfaces closer than this, and (in the implicit mode, against
    static and mocap bodies) only keep the rod from crossing the surface by the end
    of the step; a rod faster than margin / dt still can (and a resting one stays a hair
    above the surface, where a contact has no friction: speculative below lets it settle). 0 (default): contacts are
    found once the rod is inside, up to a step's travel deep. Against bodies that
    move by their own dofs MuJoCo solves the rows, and reads a margin as a skin
    the rod rests on. speculative: each step, a rod's margin grows to its fastest
    vertex's travel in the step (1.5 |v| dt, :mod:`derods.sim.speculative`; never below
    ``margin``; kept at ``margin`` while the rod travels less than 1.5 g dt^2), so a rod is
    found before it goes in however fast it moves (a stiff cable whipping down at 4.5 m/s
    at dt 1e-2 went 41 mm into a floor without it; a speculative row approached slowly
    lets the rod end its step inside by 1.5 g dt^2 at most, a resting vertex's fall, and
    it touches, with friction, from the next: a cable dragged along a floor feels 0.992 of
    Coulomb's kinetic friction, tests/test_held_rods.py). True: every rod; False: none;
    None (default): the rods held by bodies with dofs (``start_body`` / ``end_body`` with
    joints), whose contacts are solved with their holders' (without it, the held sweep's
    carts drew cables 3-14 mm into a ledge or floor at dt 1e-2, benchmarks/bench_held.py;
    a resting rod keeps its margin, so a cable lying on a floor held by a cart still steps
    in 1.33x the time of the mocap-held one, bench_world), while
    free rods and rods held by the world or by mocap bodies keep discrete detection, their
    records as they were (it changes every landing, and a fast rod makes rows for every
    surface it nears: a drop on the box edge 142 instead of 90 us a step). The implicit and
    alpha modes, and the projection mode's rods held by bodies with dofs; elsewhere True
    warns and leaves it out. holder_contact: a held edge collides with the body (with dofs)
    that holds it; off by default, as MuJoCo never collides a body with its parent
    or children. static_friction: a rod's contacts that have rested a few steps are
    anchored where they began (:mod:`derods.sim.friction`), so that below the Coulomb
    threshold they hold instead of creeping (MuJoCo's soft friction is a damper there: a
    rope on a 10 degree incline at mu = 0.3 crept 7.4 mm/s, anchored 0.001 mm/s; a heavy
    rope over a capstan slid off, anchored it holds), in the modes whose contacts derods
    solves (implicit, alpha, and rods held by bodies with dofs). Off by default for its
    cost, ~20-25 us per step with contacts (bench_world: a rod on the box edge 0.58 -> 0.78
    of the flex's step, a lying rod 0.81 -> 1.04): MuJoCo's soft friction alone.
    priority: MuJoCo's contact priority of the rods' flexes: the higher side's friction,
    solref and solimp are taken whole, equal ones mixed (MuJoCo's rule). 0 (default), as
    MuJoCo's geoms: a pad whose priority its model raised (grippers often set 1) keeps its
    own grippy contact (the grasp example: 0.76 mm of slip while carried; with the rods at
    1, tied and mixed, 6.35 mm); raise it for rods to win against geoms left at 0 (a soft
    default contact on the other side lets friction creep).
    """

    friction: float = 1.0
    solref: tuple[float, float] = (0.005, 1.0)
    solimp: tuple[float, ...] = (0.9, 0.95, 0.001, 0.5, 2.0)
    condim: int = 3
    self_collision: bool = False
    rod_rod: bool = True
    margin: float = 0.0
    speculative: bool | None = None
    holder_contact: bool = False
    static_friction: bool = False
    priority: int = 0

    def __post_init__(self):
        validation.contact_params(self)
