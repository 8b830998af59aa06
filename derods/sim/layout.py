"""Rods as MuJoCo bodies: what derods adds to a scene, and where each rod's numbers live.

Each rod becomes a chain of MuJoCo bodies, one per vertex, each with three
world-aligned slide joints (none for a vertex held by a pin or a clamp; a vertex
held by a moving body rides on it as its child), and a 1D flex over those
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

from dataclasses import dataclass

import mujoco
import numpy as np

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


def add_to_spec(spec: mujoco.MjSpec, entries: list[RodEntry], contact, collide: bool) -> None:
    """Add every rod's bodies, slide joints and collision flex to ``spec``.

    contact: :class:`derods.sim.world.ContactParams`; collide: whether the scene has
    anything the rods can touch (without, their flexes collide with nothing and MuJoCo
    does no collision work for them). A large world (over PROGRESS_FROM vertices) shows
    a progress bar on stderr.
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
    bar = None
    if total > PROGRESS_FROM:
        from tqdm import tqdm

        bar = tqdm(total=total, desc="building the world", unit="vertex", leave=False)
    for e in entries:
        _add_rod(spec, e, contact, collide, poses, bar)
    if bar is not None:
        bar.close()


def _add_rod(spec, e: RodEntry, contact, collide: bool, poses: dict, bar=None) -> None:
    rod = e.rod
    mass = rod.vertex_mass
    r = rod.material.radius
    holder = {int(i): e.holder(key) for key in ("start", "end") if e.holder(key) for i in e.held(key)}
    fixed = e.fixed
    names = []
    for i, xi in enumerate(e.x0):
        if i in holder:
            # A vertex held by a body rides on it, placed in the body's frame.
            p, rmat = poses[holder[i]]
            body = spec.body(holder[i]).add_body(name=f"{e.name}_{i}", pos=rmat.T @ (xi - p))
        else:
            body = spec.worldbody.add_body(name=f"{e.name}_{i}", pos=xi)
        body.mass = float(mass[i])
        # Vertex bodies only slide: their rotational inertia never acts, but MuJoCo refuses
        # one below mjMINVAL (a rod thinner than ~0.5 mm would have it).
        body.inertia = [max(0.5 * float(mass[i]) * r * r, INERTIA_FLOOR)] * 3
        body.explicitinertial = True
        if not fixed[i]:
            for k, axis in enumerate(np.eye(3)):
                body.add_joint(name=f"{e.name}_{i}_{'xyz'[k]}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        names.append(body.name)
        if bar is not None and i % 500 == 499:
            bar.update(500)
    if bar is not None:
        bar.update(len(e.x0) % 500)
    flex = spec.add_flex()
    flex.name = e.name
    flex.dim = 1
    flex.radius = r
    flex.vertbody = names
    j = np.arange(rod.n_edges)
    flex.elem = np.column_stack([j, (j + 1) % rod.n_vertices]).ravel().tolist()
    flex.rgba = list(e.rgba)
    flex.contype = flex.conaffinity = 1 if (collide or contact.self_collision) else 0
    flex.condim = contact.condim
    flex.friction = [contact.friction, 0.005, 0.0001]
    flex.solref = list(contact.solref)
    flex.solimp = list(contact.solimp)
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

    def rod_of_dof(self, k: int) -> int:
        """The rod owning local dof k."""
        return int(np.searchsorted(self.dof_off, k, side="right") - 1)

    def vertices(self, i: int) -> slice:
        """Rod i's range in the flat vertex arrays."""
        return slice(int(self.v_off[i]), int(self.v_off[i + 1]))
