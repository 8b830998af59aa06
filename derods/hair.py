"""Hair: many short, naturally curled rods clamped to a moving head.

The film use that made Discrete Elastic Rods famous. Each strand is a rod whose
rest shape is a helix (a curl) of its own radius, pitch, phase and hand; its
first edge is clamped to the head body of ``mjcf/head.xml`` (a mocap body), leaving
the scalp along its normal, so the roots ride on the head and the material frame
turns with it. Strands touch the skull, the neck and the shoulders (MuJoCo's
collision, derods' implicit contact step) and, by default, pass through one
another (strand-strand contact is optional: ``strand_contact=True``).

:class:`Hair` holds the parameters; :func:`scalp_sites` samples the roots,
:func:`strand_shape` curls a strand, :func:`build` makes the :class:`World`, and
:class:`Motion` drives the head (nod, shake, turn) about the neck. The measures
a hair run is judged by: :func:`penetration` (deepest strand into the skull),
:func:`root_drift` (roots leaving their sites) and :func:`max_strain`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from . import validation, scenes
from .material import Material
from .rod import Rod
from .sim.world import ContactParams, World

#: The head scene, its mocap head body, its skull geom and the site of the neck pivot.
SCENE, HEAD, SKULL, NECK = "head", "head", "skull", "neck"
#: Head motions :class:`Motion` knows.
MOTIONS = ("still", "shake", "nod", "turn")
#: Roots sit this many strand radii off the skull, so that a strand at rest does not touch it.
ROOT_LIFT = 1.5
#: Air drag on every strand vertex [1/s] (World's mass_damping).
MASS_DAMPING = 1.0
#: Strain limit [relative edge strain] of the strands (World's ``strain_limit``): a tenth
#: of the default, as hair is judged inextensible to 0.1 %.
STRAIN_LIMIT = 1e-4


@dataclass(frozen=True)
class Hair:
    """A head of hair (SI units).

    strands: number of strands. vertices: vertices per strand (the first two are
    clamped to the head). segment: edge length [m]. radius [m], young: E [Pa],
    density [kg/m^3] of a strand. curl_radius, curl_pitch: ranges [m] (min, max)
    the strands' helical rest shapes draw their radius and rise per turn from
    (a curl of radius 0 is a straight strand). seed: of the random draws (roots'
    jitter, curls, shades).
    """

    strands: int = 1000
    vertices: int = 32
    segment: float = 0.01
    radius: float = 0.001
    young: float = 3e7
    density: float = 1300.0
    curl_radius: tuple[float, float] = (0.004, 0.012)
    curl_pitch: tuple[float, float] = (0.03, 0.08)
    seed: int = 0

    def __post_init__(self):
        for name, low in (("strands", 1), ("vertices", 3)):
            value = getattr(self, name)
            if int(value) != value or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        validation.positive("segment", self.segment, "m")
        for name in ("curl_radius", "curl_pitch"):
            lo, hi = getattr(self, name)
            if not (0 <= lo <= hi and math.isfinite(hi)):
                raise ValueError(f"{name} must be a range (min, max) with 0 <= min <= max [m], got {(lo, hi)!r}")
        if self.curl_pitch[0] <= 0 and self.curl_radius[1] > 0:
            raise ValueError(f"curl_pitch must be > 0 [m] for a curled strand, got {self.curl_pitch!r}")
        self.material  # checks young, density, radius

    @property
    def material(self) -> Material:
        return Material(young=self.young, density=self.density, radius=self.radius)

    @property
    def length(self) -> float:
        """Strand length [m]."""
        return (self.vertices - 1) * self.segment


def hairline(azimuth: np.ndarray) -> np.ndarray:
    """Largest polar angle [rad] from the crown that carries hair, by azimuth [rad] (0: the
    face, +x): 45 degrees over the forehead, 115 at the nape, in between on the sides."""
    return np.radians(45.0 + 70.0 * 0.5 * (1.0 - np.cos(azimuth)))


def scalp_sites(n: int, seed: int = 0) -> np.ndarray:
    """n root directions on the scalp, unit vectors in the head's frame, shape (n, 3).

    A Fibonacci lattice over the sphere, kept where :func:`hairline` allows, thinned to n
    sites evenly over the scalp and jittered by a fraction of their spacing.
    """
    rng = np.random.default_rng(seed)
    covered = 0.5 * (1.0 - np.cos(np.radians(88.0)))  # ~ scalp share of the sphere
    m = int(n / covered) + 16
    while True:
        i = np.arange(m) + 0.5
        polar = np.arccos(1.0 - 2.0 * i / m)
        azimuth = (math.pi * (1.0 + 5 ** 0.5) * i) % (2 * math.pi)
        keep = polar <= hairline(azimuth)
        if keep.sum() >= n:
            break
        m = int(1.3 * m) + 1
    polar, azimuth = polar[keep], azimuth[keep]
    pick = np.linspace(0, len(polar) - 1, n).round().astype(int)
    polar, azimuth = polar[pick], azimuth[pick]
    spacing = math.sqrt(4 * math.pi * covered / n)
    jitter = rng.uniform(-0.25, 0.25, (2, n)) * spacing
    azimuth = azimuth + jitter[1] / np.maximum(np.sin(polar), 0.2)
    polar = np.clip(polar + jitter[0], 0.0, hairline(azimuth))
    return np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1)


def strand_shape(root: np.ndarray, normal: np.ndarray, n_vertices: int, segment: float, curl_radius: float,
                 curl_pitch: float, phase: float = 0.0, hand: int = 1) -> np.ndarray:
    """A curled strand's vertices [m], shape (n_vertices, 3).

    root: first vertex [m]; normal: unit scalp normal the first edge follows. The rest
    winds as a helix about ``normal`` of radius ``curl_radius`` [m] and rise
    ``curl_pitch`` [m] per turn (``hand`` +1 right-handed, -1 left), starting at angle
    ``phase`` [rad]; vertices are ``segment`` [m] apart along the curve.
    """
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    side = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(normal, side)
    first = np.asarray(root, float) + segment * normal
    n_rest = n_vertices - 2
    if curl_radius <= 0.0:
        rest = first + segment * np.arange(1, n_rest + 1)[:, None] * normal
    else:
        # Arc length s along a helix of radius a and rise c per radian: phi = s / sqrt(a^2 + c^2).
        c = curl_pitch / (2.0 * math.pi)
        phi = hand * segment * np.arange(1, n_rest + 1) / math.hypot(curl_radius, c)
        ring = (np.cos(phi + phase)[:, None] - math.cos(phase)) * side + \
               (np.sin(phi + phase)[:, None] - math.sin(phase)) * up
        rest = first + curl_radius * ring + (c * np.abs(phi))[:, None] * normal
        # Chords of a helix are a little shorter than its arc: space the vertices exactly.
        pts = np.concatenate([[first], rest])
        chords = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        rest = first + np.cumsum((np.diff(pts, axis=0) * (segment / chords)[:, None]), axis=0)
    return np.concatenate([[root], [first], rest])


@dataclass(frozen=True)
class Motion:
    """How the head moves: a rotation about the neck pivot, starting after ``settle`` [s].

    kind: "still", "shake" (turning left and right, amplitude 0.6 rad at 1 Hz), "nod"
    (0.25 rad at 1 Hz) or "turn" (0.9 rad to one side over 0.8 s, held, and back).
    The rotation eases in over its first half period, so the head starts from rest.
    Roots move at up to ~0.4 m/s (the crown in a nod, the temples in a shake): at
    dt = 1e-2 s a root moves 40 % of a 1 cm segment in one step, under the 50 % strain
    at which a step counts as diverged (a 0.35 rad nod reaches it).
    """

    kind: str = "shake"
    settle: float = 0.3

    def __post_init__(self):
        if self.kind not in MOTIONS:
            raise ValueError(f"motion must be one of {MOTIONS}, got {self.kind!r}")
        validation.non_negative("settle", self.settle, "s")

    def angles(self, t: float) -> tuple[float, float]:
        """(yaw about z, pitch about y) of the head [rad] at time t [s]."""
        s = t - self.settle
        if self.kind == "still" or s <= 0.0:
            return 0.0, 0.0
        ease = min(1.0, s / 0.5)
        if self.kind == "shake":
            return 0.6 * ease * math.sin(2 * math.pi * s), 0.0
        if self.kind == "nod":
            return 0.0, 0.25 * ease * math.sin(2 * math.pi * s)
        # turn: a smooth step to 0.9 rad over 0.8 s, held 1 s, and back
        def step(u):
            u = min(max(u, 0.0), 1.0)
            return 0.5 - 0.5 * math.cos(math.pi * u)
        return 0.9 * (step(s / 0.8) - step((s - 1.8) / 0.8)), 0.0

    def pose(self, t: float, center: np.ndarray, pivot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Head position [m] (3,) and orientation quaternion (4,) at time t, turning about
        ``pivot`` from a head at rest at ``center``."""
        yaw, pitch = self.angles(t)
        q = np.empty(4)
        mujoco.mju_euler2Quat(q, np.array([0.0, pitch, yaw]), "xyz")
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, q)
        return pivot + rot.reshape(3, 3) @ (center - pivot), q


def strands(hair: Hair, centre: np.ndarray, skull_radius: float) -> list[np.ndarray]:
    """Every strand's rest vertices [m], each (vertices, 3), rooted ROOT_LIFT radii off a
    skull of ``skull_radius`` [m] at ``centre`` [m] (head unturned), curled as drawn
    from ``hair.seed``."""
    rng = np.random.default_rng(hair.seed + 1)
    lift = skull_radius + ROOT_LIFT * hair.radius
    out = []
    for n in scalp_sites(hair.strands, hair.seed):
        out.append(strand_shape(np.asarray(centre) + lift * n, n, hair.vertices, hair.segment,
                                rng.uniform(*hair.curl_radius), rng.uniform(*hair.curl_pitch),
                                rng.uniform(0.0, 2 * math.pi), int(rng.choice([-1, 1]))))
    return out


def build(hair: Hair = Hair(), dt: float = 1e-2, strand_contact: bool = False, friction: float = 0.3,
          mass_damping: float = MASS_DAMPING, margin: float = 0.01) -> World:
    """A :class:`World` of the head scene with ``hair`` clamped to its head.

    dt: time step [s]. strand_contact: strands touch one another (off: they pass
    through, and only touch the skull, neck and shoulders). friction: strand-body
    friction coefficient. mass_damping [1/s]: air drag on every vertex. margin [m]:
    the contacts' speculative margin (see :class:`ContactParams`): strands swung
    into the skull at ~0.5 m/s travel 5 mm a step, and are stopped at its surface
    instead of being found inside it (1000 strands nodding for 3 s: deepest
    penetration 0.2 mm with 1 cm, 3.7 mm with 5 mm; 300 shaken, after the first
    impact: 0.15 mm with 5 mm, 4.4 mm with none).
    Strands are named ``hair0``, ``hair1``, ...; the head does not move until a
    :class:`Motion` drives it (see :func:`drive`).
    """
    spec = mujoco.MjSpec.from_file(str(scenes.path(SCENE)))
    world = World(spec, dt=dt, mode="implicit", mass_damping=mass_damping, strain_limit=STRAIN_LIMIT,
                  contact=ContactParams(friction=friction, rod_rod=strand_contact, margin=margin))
    centre = np.asarray(spec.body(HEAD).pos, float)
    mat = hair.material
    rng = np.random.default_rng(hair.seed + 2)
    for k, x in enumerate(strands(hair, centre, float(spec.geom(SKULL).size[0]))):
        shade = rng.uniform(0.75, 1.25)
        rgba = (min(1.0, 0.27 * shade), min(1.0, 0.16 * shade), min(1.0, 0.08 * shade), 1.0)
        world.add_rod(Rod(x, mat), f"hair{k}", start="clamp", start_body=HEAD, rgba=rgba)
    return world


def drive(world: World, motion: Motion):
    """A ``before_step(world)`` callback that poses the head for ``motion`` at the world's
    time (call it before every step; :func:`derods.viz.filming.film` does)."""
    model = world.model
    body = model.body(HEAD)
    mocap = int(model.body_mocapid[body.id])
    center = model.body_pos[body.id].copy()
    pivot = model.site(NECK).pos.copy()

    def before_step(w):
        pos, quat = motion.pose(w.time + w.model.opt.timestep, center, pivot)
        w.data.mocap_pos[mocap] = pos
        w.data.mocap_quat[mocap] = quat

    return before_step


def skull_pose(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, float]:
    """Skull centre [m] (3,), head orientation (3, 3) and skull radius [m] as the head's
    mocap pose sets them now (whether or not MuJoCo's kinematics ran since)."""
    body = model.body(HEAD).id
    mocap = int(model.body_mocapid[body])
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, data.mocap_quat[mocap])
    rot = rot.reshape(3, 3)
    g = model.geom(SKULL).id
    return data.mocap_pos[mocap] + rot @ model.geom_pos[g], rot, float(model.geom_size[g, 0])


def strand_positions(world: World) -> np.ndarray:
    """Every strand's vertices [m], shape (strands, vertices, 3) (strands are of one size)."""
    return world.all_positions().reshape(len(world.rods), -1, 3)


def sphere_penetration(x: np.ndarray, centre: np.ndarray, sphere_radius: float, strand_radius: float) -> float:
    """Deepest penetration [m] of strands x [m] (strands, vertices, 3), capsules of
    ``strand_radius`` [m] along each edge, into a sphere; 0 if none touches it."""
    a, b = x[:, :-1], x[:, 1:]
    d = b - a
    s = np.clip(np.einsum("rei,rei->re", centre - a, d) / np.maximum(np.einsum("rei,rei->re", d, d), 1e-300), 0, 1)
    gap = np.linalg.norm(a + s[..., None] * d - centre, axis=-1) - sphere_radius - strand_radius
    return float(max(0.0, -gap.min()))


def penetration(world: World) -> float:
    """Deepest penetration [m] of any strand (a capsule of its radius along each edge)
    into the skull, now; 0 if none touches it."""
    c, _, skull = skull_pose(world.model, world.data)
    return sphere_penetration(strand_positions(world), c, skull, world.rods[0].material.radius)


def root_offset(roots: np.ndarray, hair: Hair, centre: np.ndarray, rot: np.ndarray, skull_radius: float) -> float:
    """Largest distance [m] of roots (strands, 3) [m] from their scalp sites on a skull of
    ``skull_radius`` [m] at ``centre`` [m] turned by ``rot`` (3, 3)."""
    want = centre + (skull_radius + ROOT_LIFT * hair.radius) * scalp_sites(hair.strands, hair.seed) @ rot.T
    return float(np.linalg.norm(roots - want, axis=1).max())


def edge_strain(x: np.ndarray, rest) -> float:
    """Largest |edge length / rest length - 1| of strands x (strands, vertices, 3) [m];
    rest [m]: one length, or (strands, vertices - 1)."""
    return float(np.abs(np.linalg.norm(np.diff(x, axis=1), axis=-1) / rest - 1.0).max())


def root_drift(world: World, hair: Hair) -> float:
    """Largest distance [m] of a strand's root vertex from its scalp site (which moves with
    the head), now: clamped roots ride on the head, so this stays at round-off."""
    return root_offset(strand_positions(world)[:, 0], hair, *skull_pose(world.model, world.data))


def max_strain(world: World) -> float:
    """Largest |edge length / rest length - 1| over every strand, now."""
    return edge_strain(strand_positions(world), np.stack([r.rest_len for r in world.rods]))
