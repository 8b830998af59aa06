"""Rods as MuJoCo bodies: what derods adds to a scene, and where each rod's numbers live.

Each rod becomes a static body of its name holding a chain of MuJoCo bodies, one
per vertex, each with three world-aligned slide joints (none for a vertex held
by a pin or a clamp; a vertex held by a moving body rides on it as its child
instead), and a 1D flex over those
bodies with no MuJoCo elasticity: the flex only makes the edges collide as
capsules of the rod radius (thin obstacles cannot slip between vertices).
Everything elastic comes from derods.

:func:`add_to_spec` builds that into an ``MjSpec``; once it is compiled,
:class:`Layout` is the frozen map between derods' flat arrays (vertices of all
rods laid end to end; the free vertices in their solve order, a ring's
zig-zagged by :func:`derods.stencil.ring_order`) and MuJoCo's (bodies, qpos,
dofs). It is built once and read every step.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np

from .._numba.implicit import Places
from ..rod import Rod
from ..stencil import RING_BANDWIDTH, XX_BANDWIDTH, ring_order

#: How an end is held, and how many of its vertices that holds.
END_KINDS = ("free", "pin", "clamp")
HELD = {"free": 0, "pin": 1, "clamp": 2}
#: Rotational inertia [kg m^2] given to vertex bodies at the least (MuJoCo's mjMINVAL is 1e-15).
INERTIA_FLOOR = 1e-12


@dataclass(frozen=True)
class RodEntry:
    """A rod as added to a world: its name, the rod (with the twist boundary its ends
    impose), initial positions x0 [m] (n_vertices, 3), how each end is held ("free",
    "pin", "clamp"), the scene bodies holding the ends (None: the world) and its colour."""

    name: str
    rod: Rod
    x0: np.ndarray
    start: str = "free"
    end: str = "free"
    start_body: str | None = None
    end_body: str | None = None
    rgba: tuple = (0.85, 0.25, 0.15, 1.0)

    def held(self, key: str) -> np.ndarray:
        """Vertex indices held by the "start" or "end"."""
        nv = self.rod.n_vertices
        k = HELD[self.start if key == "start" else self.end]
        return np.arange(k) if key == "start" else np.arange(nv - k, nv)

    @property
    def fixed(self) -> np.ndarray:
        """Which vertices are held (have no dofs), shape (n_vertices,), bool."""
        mask = np.zeros(self.rod.n_vertices, dtype=bool)
        mask[self.held("start")] = True
        mask[self.held("end")] = True
        return mask

    def holder(self, key: str) -> str | None:
        return self.start_body if key == "start" else self.end_body


#: Worlds with more vertices than this show progress while they are built.
PROGRESS_FROM = 3000
#: Rod vertices built per MjSpec before it is attached to the scene. MuJoCo's
#: ``add_body`` rebuilds the spec's element lists (time linear in the spec's size)
#: and ``attach`` re-indexes every name of the parent (linear in the parent's size),
#: so building all bodies in one spec costs N^2 and attaching rod by rod costs
#: N * R; chunks of ~1000 vertices keep both small (measured at 1000 rods x 32
#: vertices: 3.2 s, against ~60 s for one spec; benchmarks/bench_hair.py).
CHUNK_VERTICES = 1000
#: MuJoCo's arena guess grows as ~46 nv^2 bytes (15 GB at 19,200 dofs; it fails
#: to allocate beyond), so a world with more rod dofs than this gets its own
#: budget instead, unless its scene sets ``<size memory>`` itself.
ARENA_GUESS_UP_TO = 3000
#: That budget [bytes]: a base, so much per dof (contacts, constraint rows and the
#: solver's sparse factor of a rod world need far less), and the broadphase's pair
#: list, which mj_collision reserves for every pair of bodies and flexes (an int
#: each: 2 n^2 bytes; only the pairs found are ever written).
ARENA_BASE, ARENA_PER_DOF = 64 << 20, 4 << 10
#: The budget's factor when every rod has speed-sized contact margins
#: (``ContactParams(speculative=True)``): a landing rod's margin grows with its speed and
#: finds every pair within it. Measured: 100 cables of 41 vertices dropped into a heap
#: used 165 MB at most, the plain budget being 147 MB (MuJoCo stopped the step, CNSTRFULL).
SPECULATIVE_ARENA = 2


#: The world axes of a vertex body's three slide joints.
AXES = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])


def arena_budget(n_dofs: int, n_bodies_flexes: int) -> int:
    """MuJoCo arena [bytes] for a world of ``n_dofs`` dofs and that many bodies plus flexes."""
    return ARENA_BASE + ARENA_PER_DOF * n_dofs + 2 * n_bodies_flexes ** 2


def element_bodies(model: mujoco.MjModel) -> np.ndarray:
    """The two vertex bodies of every element of the model's 1D flexes (the rods' edges),
    int64, shape (max(nflexelem, 1), 2); -1 for the elements of other flexes."""
    out = np.full((max(int(model.nflexelem), 1), 2), -1, dtype=np.int64)
    for f in range(model.nflex):
        if model.flex_dim[f] != 1:
            continue
        adr, num = int(model.flex_elemdataadr[f]), int(model.flex_elemnum[f])
        verts = model.flex_elem[adr:adr + 2 * num].reshape(num, 2) + model.flex_vertadr[f]
        out[model.flex_elemadr[f]:model.flex_elemadr[f] + num] = model.flex_vertbodyid[verts]
    return out


def add_to_spec(spec: mujoco.MjSpec, entries: list[RodEntry], contact, collide: bool) -> None:
    """Add every rod's bodies, slide joints and collision flex to ``spec``.

    contact: :class:`derods.sim.contact_params.ContactParams`; collide: whether the scene has
    anything the rods can touch (without, their flexes collide with nothing and MuJoCo
    does no collision work for them). A large world (over PROGRESS_FROM vertices) shows
    a progress bar on stderr.

    Each rod gets a static body of its own name, child of the world, holding its
    vertex bodies ``f"{name}_{i}"`` (MuJoCo still treats them as "simple" bodies: a
    diagonal mass matrix, and a compile linear in their number); a vertex held by a
    scene body is that body's child instead.
    """
    poses = {}
    holders = {e.holder(k) for e in entries for k in ("start", "end")} - {None}
    if holders:
        # World poses of the bodies that hold rod ends, at the scene's initial state.
        base = spec.compile()
        bdata = mujoco.MjData(base)
        mujoco.mj_kinematics(base, bdata)
        for body in holders:
            b = base.body(body).id
            poses[body] = (bdata.xpos[b].copy(), bdata.xmat[b].reshape(3, 3).copy())
    total = sum(e.rod.n_vertices for e in entries)
    n_dofs = 3 * sum(int(np.sum(~e.fixed)) for e in entries)
    if spec.memory == -1 and n_dofs > ARENA_GUESS_UP_TO:
        n_bf = len(spec.bodies) + len(spec.flexes) + total + 2 * len(entries)
        spec.memory = arena_budget(n_dofs, n_bf) * (SPECULATIVE_ARENA if contact.speculative is True else 1)
    bar = None
    if total > PROGRESS_FROM:
        from tqdm import tqdm

        bar = tqdm(total=total, desc="building the world", unit="vertex", leave=False)
    # Vertices riding on scene bodies first, while the scene's spec is small.
    for e in entries:
        for key in ("start", "end"):
            if e.holder(key):
                p, rmat = poses[e.holder(key)]
                for i in e.held(key):
                    _vertex_body(spec.body(e.holder(key)), e, int(i), rmat.T @ (e.x0[i] - p), joints=False,
                                 mass=float(e.rod.vertex_mass[i]))
    chunks, size = [], CHUNK_VERTICES
    for e in entries:
        if size >= CHUNK_VERTICES:
            chunks.append(mujoco.MjSpec())
            size = 0
        _add_rod_bodies(chunks[-1].worldbody, e)
        size += e.rod.n_vertices
        if bar is not None:
            bar.update(e.rod.n_vertices)
    # Merged pairwise (each attach costs time linear in the spec attached to), then
    # attached to the scene once: N log N in all, where attaching chunk by chunk to the
    # scene costs N^2 / CHUNK_VERTICES.
    while len(chunks) > 1:
        for k in range(0, len(chunks) - 1, 2):
            _attach(chunks[k], chunks[k + 1])
        chunks = chunks[::2]
    if chunks:
        _attach(spec, chunks[0])
    for e in entries:
        _add_flex(spec, e, contact, collide)
    if bar is not None:
        bar.close()


def _vertex_body(parent, e: RodEntry, i: int, pos, joints: bool, mass: float):
    """Vertex i of rod e, of ``mass`` [kg], as a body under ``parent`` at ``pos`` (in the
    parent's frame)."""
    rod = e.rod
    body = parent.add_body(name=f"{e.name}_{i}", pos=pos)
    body.mass = mass
    # Vertex bodies only slide: their rotational inertia never acts, but MuJoCo refuses
    # one below mjMINVAL (a rod thinner than ~0.5 mm would have it).
    body.inertia = [max(0.5 * mass * rod.material.radius ** 2, INERTIA_FLOOR)] * 3
    # The centre of mass at the body's origin makes it a "simple" body to MuJoCo.
    body.ipos = [0.0, 0.0, 0.0]
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    body.explicitinertial = True
    if joints:
        for axis in AXES:
            body.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
    return body


def _add_rod_bodies(worldbody, e: RodEntry) -> None:
    """Rod e's static body and its vertex bodies (all but those riding on scene bodies)."""
    root = worldbody.add_body(name=e.name)
    riding = {int(i) for key in ("start", "end") if e.holder(key) for i in e.held(key)}
    fixed = e.fixed
    mass = e.rod.vertex_mass.tolist()  # a property that computes them all
    for i, xi in enumerate(e.x0):
        if i not in riding:
            _vertex_body(root, e, i, xi, joints=not fixed[i], mass=mass[i])


def _attach(spec: mujoco.MjSpec, chunk: mujoco.MjSpec) -> None:
    """Attach a chunk of rods at the world's origin, keeping its names as they are.

    MuJoCo warns that an empty prefix "may prevent the model from being saved
    correctly"; the names are unique (rod names are), and ``to_xml`` saves them, so
    that one warning is swallowed and any other is passed on.
    """
    previous = mujoco.get_mju_user_warning()

    def warn(msg):
        if "empty prefix" not in msg:
            warnings.warn(f"MuJoCo: {msg}", stacklevel=3)

    mujoco.set_mju_user_warning(warn)
    try:
        spec.attach(chunk, frame=spec.worldbody.add_frame(), prefix="")
    finally:
        mujoco.set_mju_user_warning(previous)


def _add_flex(spec: mujoco.MjSpec, e: RodEntry, contact, collide: bool) -> None:
    rod = e.rod
    flex = spec.add_flex()
    flex.name = e.name
    flex.dim = 1
    flex.radius = rod.material.radius
    flex.vertbody = [f"{e.name}_{i}" for i in range(rod.n_vertices)]
    j = np.arange(rod.n_edges)
    flex.elem = np.column_stack([j, (j + 1) % rod.n_vertices]).ravel().tolist()
    flex.rgba = list(e.rgba)
    touches = collide or contact.self_collision
    flex.contype = 1 if touches else 0
    # Rods touch one another unless told not to (hair: strands pass through each other).
    flex.conaffinity = 1 if touches and (contact.rod_rod or contact.self_collision) else 0
    flex.condim = contact.condim
    flex.friction = [contact.friction, 0.005, 0.0001]
    flex.solref = list(contact.solref)
    flex.solimp = list(contact.solimp)
    flex.margin = contact.margin
    flex.priority = contact.priority
    flex.selfcollide = (mujoco.mjtFlexSelf.mjFLEXSELF_AUTO if contact.self_collision
                        else mujoco.mjtFlexSelf.mjFLEXSELF_NONE)


@dataclass(frozen=True)
class Layout:
    """Where the rods' numbers live in MuJoCo (built once, at compile).

    Vertices of all rods are laid end to end (rod i owns v_off[i]:v_off[i + 1]); the
    free vertices form the "places" of the solve order, rod after rod, and each place
    owns three local dofs (3 p .. 3 p + 2).

    names: rod names. v_off (n_rods + 1,): vertex offsets. x0 (n_vertices, 3) [m]: the
    bodies' initial positions (a free vertex is x0 plus its slide joints' qpos). body
    (n_vertices,): each vertex's MuJoCo body. place (n_vertices,): each vertex's place,
    -1 if held. free_vertex, free_body, qpos_adr (n_places,): each place's vertex, body
    and first of its three qpos entries. dofs (n,), mass (n,) [kg]: each local dof's
    MuJoCo dof and mass. dof_off (n_rods + 1,): each rod's local dof range. local_of_dof
    (nv,): each MuJoCo dof's local dof, -1 if not a rod's. moved_vertex, moved_body
    (n_moved,): vertices held by moving bodies and the MuJoCo bodies they are (their
    positions come from xpos). band_rows: rows of the step's band (15 with a ring, else 9).
    """

    names: tuple
    v_off: np.ndarray
    x0: np.ndarray
    body: np.ndarray
    place: np.ndarray
    free_vertex: np.ndarray
    free_body: np.ndarray
    qpos_adr: np.ndarray
    dofs: np.ndarray
    mass: np.ndarray
    dof_off: np.ndarray
    local_of_dof: np.ndarray
    moved_vertex: np.ndarray
    moved_body: np.ndarray
    band_rows: int

    @classmethod
    def build(cls, model: mujoco.MjModel, entries: list[RodEntry]) -> "Layout":
        nv_rod = [e.rod.n_vertices for e in entries]
        v_off = np.concatenate([[0], np.cumsum(nv_rod)]).astype(np.int64)
        body = np.concatenate([[model.body(f"{e.name}_{i}").id for i in range(e.rod.n_vertices)]
                               for e in entries]).astype(np.int64)
        place = np.full(int(v_off[-1]), -1, dtype=np.int64)
        order_all, moved = [], []
        for i, e in enumerate(entries):
            fixed = e.fixed
            order = ring_order(e.rod.n_vertices) if e.rod.closed else np.flatnonzero(~fixed)
            order_all.append(v_off[i] + order)
            for key in ("start", "end"):
                if e.holder(key):
                    moved.extend(v_off[i] + e.held(key))
        free_vertex = np.concatenate(order_all).astype(np.int64)
        place[free_vertex] = np.arange(len(free_vertex))
        free_body = body[free_vertex]
        jnt = model.body_jntadr[free_body]
        qpos_adr = model.jnt_qposadr[jnt].astype(np.int64)
        # The three slide joints of a body are consecutive in qpos and qvel.
        assert np.all(model.jnt_qposadr[jnt + 2] == qpos_adr + 2)
        dofs = (model.body_dofadr[free_body][:, None] + np.arange(3)).ravel().astype(np.int64)
        mass = np.repeat(model.body_mass[free_body], 3)
        n_free = [int(np.sum(~e.fixed)) for e in entries]
        dof_off = 3 * np.concatenate([[0], np.cumsum(n_free)]).astype(np.int64)
        local_of_dof = np.full(model.nv, -1, dtype=np.int64)
        local_of_dof[dofs] = np.arange(len(dofs))
        x0 = np.concatenate([e.x0 for e in entries]).astype(float)
        moved = np.array(moved, dtype=np.int64)
        rows = (RING_BANDWIDTH if any(e.rod.closed for e in entries) else XX_BANDWIDTH) + 1
        return cls(tuple(e.name for e in entries), v_off, x0, body, place, free_vertex, free_body, qpos_adr,
                   dofs, mass, dof_off, local_of_dof, moved, body[moved], rows)

    @property
    def n(self) -> int:
        """Number of local dofs (three per free vertex)."""
        return len(self.dofs)

    @cached_property
    def places(self) -> Places:
        """free_vertex, free_body and dofs as the compiled step takes them."""
        return Places(self.free_vertex, self.free_body, self.dofs)

    def rod_of_dof(self, k: int) -> int:
        """The rod owning local dof k."""
        return int(np.searchsorted(self.dof_off, k, side="right") - 1)

    def vertices(self, i: int) -> slice:
        """Rod i's range in the flat vertex arrays."""
        return slice(int(self.v_off[i]), int(self.v_off[i + 1]))
