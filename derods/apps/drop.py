"""Drop rods onto a rigid scene and film it: the ``derods drop`` command.

A scene is an MJCF file: one of derods' own in ``mjcf/`` by name (floor, box,
table_edge, stairs, pegs, halfpipe, rail) or any path. Rods are released
above the scene's site named "drop" (its size sets the spread; (0, 0, 1) m
when the scene has none), one above the other so they land one after the
other, each turned about the vertical so they cross.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from .. import scenes, shapes
from ..viz import filming, output
from ..material import Material
from ..rod import Rod
from ..twist import TwistBoundary
from ..sim import scene_checks
from ..sim.divergence import DivergenceError
from ..sim.world import ContactParams, World

SHAPES = ("straight", "helix", "bezier", "ring")
OVERLAYS = ("none", "frames", "bend", "twist")
#: Default control points of the "bezier" shape (scaled to the rod length).
BEZIER_CONTROL = np.array([[0, 0, 0], [0.3, 0.5, 0], [0.6, -0.5, 0], [1.0, 0, 0],
                           [1.3, 0.4, 0], [1.6, -0.2, 0], [2.0, 0.1, 0]]) * 0.5
#: Rod colours (RGBA), cycled: warm and saturated, to stand out from the grey-blue scenes.
COLOURS = [(0.9, 0.3, 0.15, 1), (0.95, 0.7, 0.1, 1), (0.2, 0.65, 0.3, 1), (0.75, 0.2, 0.55, 1),
           (0.15, 0.55, 0.85, 1), (0.55, 0.35, 0.2, 1)]


@dataclass(frozen=True)
class DropParams:
    """What to drop and how to film it.

    scene: scene name or MJCF path. rods: number of rods. shape: "straight",
    "helix", "bezier" (through ``control``, C1) or "ring" (a closed rod, naturally
    round like an O-ring). control: Bezier control points, shape (3k+1, 3), scaled
    to the rod length; None for a default wave. n_edges: edges per rod. length:
    rod length [m].
    seconds: simulated time [s]. dt: time step [s]. fps: video frames per
    second. width, height: video size [pixels]. camera: camera name (None: the
    scene's "main", else MuJoCo's free camera). material: the rods' material.
    mass_damping: drag rate [1/s]. seed: random seed of the placement.
    mode: the World's time stepping (:data:`derods.MODES`).
    overlay: "none", "frames" (material frames as arrows: m1 pink, m2 green),
    "bend" (rods coloured by bending strain r kappa, blue straight to red at 5 %)
    or "twist" (coloured by twisting strain r tau, the same scale).
    """

    scene: str = "box"
    rods: int = 3
    shape: str = "straight"
    n_edges: int = 40
    length: float = 0.8
    seconds: float = 4.0
    dt: float = 2e-3
    fps: float = 30.0
    width: int = 960
    height: int = 540
    camera: str | None = None
    material: Material = Material(young=2e6, radius=0.008, density=1100.0)
    mass_damping: float = 0.5
    seed: int = 0
    overlay: str = "none"
    control: np.ndarray | None = None
    mode: str = "auto"

    def __post_init__(self):
        if self.overlay not in OVERLAYS:
            raise ValueError(f"overlay must be one of {OVERLAYS}, got {self.overlay!r}")
        if self.shape not in SHAPES:
            raise ValueError(f"shape must be one of {SHAPES}, got {self.shape!r}")
        if int(self.rods) != self.rods or self.rods < 1:
            raise ValueError(f"rods must be an integer >= 1, got {self.rods!r}")
        if int(self.n_edges) != self.n_edges or self.n_edges < 2:
            raise ValueError(f"n_edges must be an integer >= 2, got {self.n_edges!r}")
        for name, unit in (("length", "m"), ("seconds", "s"), ("dt", "s"), ("fps", "1/s")):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0 [{unit}], got {v!r}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if int(v) != v or v <= 0:
                raise ValueError(f"{name} must be a positive integer [pixels], got {v!r}")


def rod_shape(shape: str, length: float, n_edges: int, control=None) -> np.ndarray:
    """A rod of the given shape and arc length, centred at the origin, lying along x
    (a ring: in the xy plane)."""
    if shape == "ring":
        return shapes.circle(length / (2 * math.pi), n_edges)
    if shape == "straight":
        x = shapes.straight(length, n_edges)
    elif shape == "helix":
        turns, radius = 2.0, 0.06
        pitch = math.sqrt(max((length / turns) ** 2 - (2 * math.pi * radius) ** 2, 1e-6))
        x = shapes.helix(radius, pitch, turns, n_edges)[:, [2, 0, 1]]  # axis along x
    else:
        c = BEZIER_CONTROL if control is None else np.asarray(control, float)
        x = shapes.bezier(c, n_edges, "C1")
        x *= length / np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1))
    return x - x.mean(axis=0)


def build_world(p: DropParams, notes=None) -> World:
    """The scene with ``p.rods`` rods placed above its drop site, ready to film.

    What a video needs and the scene lacks is added, and ``notes(text)`` (if given) is told:
    an offscreen buffer of the video's size, a light, a camera "main" that frames the rods.
    A rod that starts inside an obstacle, or an obstacle thinner than a falling rod's travel
    in one step, is reported through ``notes`` too (:mod:`derods.sim.scene_checks`).
    """
    path = scenes.path(p.scene)
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as err:
        raise ValueError(f"cannot read MJCF scene {str(path)!r}: {err}") from None
    note = notes or (lambda text: None)
    site = next((s for s in spec.sites if s.name == "drop"), None)
    centre = np.array(site.pos, dtype=float) if site is not None else np.array([0.0, 0.0, 1.0])
    spread = float(site.size[0]) if site is not None else 0.3
    # The scene's checks are this command's own: a dt too long for the fall is refused
    # (check_step) and the rest noted, not warned.
    world = World(spec, dt=p.dt, mode=p.mode, mass_damping=p.mass_damping, contact=ContactParams(friction=0.8),
                  scene_checks=False)
    rng = np.random.default_rng(p.seed)
    base = rod_shape(p.shape, p.length, p.n_edges, p.control)
    ring = p.shape == "ring"
    placed = []
    for i in range(p.rods):
        yaw = math.pi * i / p.rods + rng.uniform(-0.2, 0.2)
        rot = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
        offset = np.array([*rng.uniform(-0.3, 0.3, size=2) * spread, 0.12 * i])
        x = base @ rot.T + centre + offset
        placed.append(x)
        rod = Rod(x, p.material, closed=True, boundary=TwistBoundary("ring")) if ring else Rod(x, p.material)
        world.add_rod(rod, f"rod{i}", rgba=COLOURS[i % len(COLOURS)])
    for text in prepare_for_video(spec, p.width, p.height, np.concatenate(placed), p.camera is None):
        note(text)
    world.compile()
    for text in starts_inside(world):
        note(text)
    tops = [float(x[:, 2].max()) for x in placed]
    if scene_checks.fall_step(world.model, world.data, tops, [float(r.length) for r in world.rods]) is None:
        # (A dt too long for the fall is refused by check_step, which says more.)
        for text in scene_checks.thin_geoms(world.model, world.data, tops, p.material.radius):
            note(text)
    return world


def prepare_for_video(spec: mujoco.MjSpec, width: int, height: int, rods: np.ndarray, need_camera: bool) -> list:
    """Add to ``spec`` what a video of it needs and it lacks; returns what was added, in words.

    An offscreen buffer of at least width x height [pixels]; a directional light from above
    if the scene has no light; a camera "main" looking at the rods' start (rods: their
    vertices [m], shape (n, 3)) from the front and above, if need_camera and it has none.
    """
    added = []
    g = spec.visual.global_
    if g.offwidth < width or g.offheight < height:
        added.append(f"the scene's offscreen buffer is {g.offwidth}x{g.offheight}; made it "
                     f"{max(g.offwidth, width)}x{max(g.offheight, height)} for the video")
        g.offwidth, g.offheight = max(g.offwidth, width), max(g.offheight, height)
    if not spec.lights:
        # No shadow: a shadow map sized for an unknown scene's extent speckles large planes.
        spec.worldbody.add_light(name="derods_light", pos=[0.0, 0.0, 5.0], dir=[0.3, 0.3, -1.0],
                                 type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, diffuse=[0.6, 0.6, 0.6],
                                 castshadow=False)
        spec.visual.headlight.ambient = [0.35, 0.35, 0.38]
        spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
        added.append("the scene has no light; added a directional light from above and a brighter headlight")
    if need_camera and not any(c.name == "main" for c in spec.cameras):
        # Frame the fall: from where the rods start down to the scene's lowest geom (its floor).
        lo, hi = rods.min(axis=0), rods.max(axis=0)
        floor = min([float(g.pos[2]) for g in spec.worldbody.geoms] + [float(lo[2]) - 1.0])
        target = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (hi[2] + floor)])
        dist = 1.2 * float(np.linalg.norm(hi[:2] - lo[:2])) + 1.3 * float(hi[2] - floor) + 0.3
        elev = math.radians(30.0)
        pos = target + dist * np.array([0.0, -math.cos(elev), math.sin(elev)])
        fwd = (target - pos) / np.linalg.norm(target - pos)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        spec.worldbody.add_camera(name="main", pos=pos, xyaxes=np.concatenate([right, up]))
        added.append(f"the scene has no camera 'main'; added one looking at the rods from {np.round(pos, 2).tolist()} m")
    return added


def deepest_contact(world: World) -> tuple[float, str | None, float]:
    """(depth [m], rod name, rod radius [m]) of the deepest contact between a rod and
    anything; (0, None, 0) without contacts. From the contacts of MuJoCo's last forward pass."""
    m, d = world.model, world.data
    deepest, who, radius = 0.0, None, 0.0
    flexes = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, n): i for i, n in enumerate(world.rod_names)}
    for c in d.contact[: d.ncon]:
        for f in (c.flex[0], c.flex[1]):
            if f in flexes and -c.dist > deepest:
                i = flexes[f]
                deepest, who, radius = -c.dist, world.rod_names[i], world.rods[i].material.radius
    return deepest, who, radius


def contacts_held(world: World, end: bool) -> None:
    """Raise DivergenceError if rods went through the scene: during a run, a contact deeper
    than half a rod's length (it is through the obstacle); at its end, deeper than 4 radii
    plus 1 cm (resting rods sink 0.02-2 mm at r = 10 mm, set mostly by the contacts'
    softness, solimp's 1 mm width, whatever the radius; a run that ends during an impact
    sees up to 1.7 r at 3 m/s; a dt at which contacts do not hold sinks rods by metres)."""
    depth, who, radius = deepest_contact(world)
    if who is None:
        return
    i = world.rod_names.index(who)
    limit = 4.0 * radius + 0.01 if end else 0.5 * float(world.rods[i].length)
    if depth > limit:
        dt = world.model.opt.timestep
        raise DivergenceError(f"rod {who!r} went into the scene: a contact {1000 * depth:.1f} mm deep at "
                              f"t = {world.time:.4g} s (radius {1000 * radius:g} mm); contacts did not hold at "
                              f"dt = {dt:g} s: use a smaller dt")


def check_step(world: World) -> None:
    """Refuse a dt at which a rod falling from where it starts would move more than half
    its length in one step at impact: no contact can hold that (it would pass through
    obstacles within a step). Smaller steps that still lose contact are caught while the
    video is made (:func:`contacts_held`)."""
    tops = [float(world.positions(i)[:, 2].max()) for i in range(len(world.rods))]
    refusal = scene_checks.fall_step(world.model, world.data, tops, [float(r.length) for r in world.rods])
    if refusal is not None:
        raise ValueError(refusal)


def starts_inside(world: World) -> list:
    """Rods that start inside an obstacle (a contact deeper than their radius), in words."""
    m, d = world.model, world.data
    mujoco.mj_forward(m, d)
    return scene_checks.starts_inside(m, d, world.rod_names, [r.material.radius for r in world.rods])


def overlay_painter(world: World, kind: str):
    """A scene callback that draws ``kind`` ("frames" or "bend") for every rod, or None."""
    from .. import frames
    from ..viz import overlay

    if kind == "none":
        return None
    if kind in ("bend", "twist"):
        world.model.flex_rgba[:, 3] = 0.0  # the coloured tube replaces the flex

    def paint(scene):
        for i, rod in enumerate(world.rods):
            x = world.positions(i)
            if kind == "frames":
                st = world.rod_state(i)
                m1, m2 = frames.material_frames(st.u, frames.tangents(x, rod.closed), st.theta)
                h = float(np.mean(rod.rest_len))
                xx = np.concatenate([x, x[:1]]) if rod.closed else x
                overlay.add_frames(scene, xx, m1, m2, length=4.0 * h, width=0.7 * rod.material.radius,
                                   every=max(1, len(m1) // 20))
            else:
                rate = (overlay.bending_strain(x, rod.closed) if kind == "bend"
                        else overlay.twisting_strain(rod, world.rod_state(i)))
                colours = overlay.strain_colours(rate, vmax=0.05 / rod.material.radius)
                overlay.add_tube(scene, x, rod.material.radius, colours, closed=rod.closed)

    return paint


def drop(p: DropParams, out, progress: bool = True, still=None, quality: str = "auto", notes=None) -> dict:
    """Simulate ``p`` and write an MP4 to ``out``; returns a summary dict.

    still: optional PNG path for the last frame (overlays included). quality: render
    quality (:mod:`derods.viz.render`). notes: optional ``f(text)`` told what derods added
    to a scene for its video, and what looks wrong (a rod starting inside an obstacle).
    The files appear only once complete.
    """
    out, still = output.check_outputs(out, still)
    filming.frame_plan(p.seconds, p.fps, p.dt)  # refuse a mismatched time, fps or dt before any work
    world = build_world(p, notes)
    check_step(world)
    cam_name = p.camera
    if cam_name is None and mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, "main") >= 0:
        cam_name = "main"
    paint = overlay_painter(world, p.overlay)
    result = filming.film(world, out, p.seconds, p.fps, p.width, p.height, cam_name, paint=paint, progress=progress,
                          label=f"drop {p.scene}", quality=quality, after_frame=lambda w: contacts_held(w, False),
                          before_close=lambda w: contacts_held(w, True))
    if still is not None:
        output.write_image(still, result["last"])
    return {"out": str(out), "frames": result["frames"], "sim_s": world.time, "steps": world.n_steps,
            "rods": world.rod_names, "mode": world.mode, "quality": result["quality"]}
