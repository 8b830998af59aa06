"""Drop rods onto a rigid scene and film it: the ``derods drop`` command.

A scene is an MJCF file: one of derods' own in ``mjcf/`` by name (floor, box,
table_edge, stairs, pegs, halfpipe, rail) or any path. Rods are released
above the scene's site named "drop" (its size sets the spread; (0, 0, 1) m
when the scene has none), one above the other so they land one after the
other, each turned about the vertical so they cross.
"""

from __future__ import annotations

import math
import pathlib
from dataclasses import dataclass

import mujoco
import numpy as np

from .. import shapes
from ..viz import render
from ..rod import Material, Rod
from ..twist import TwistBoundary
from ..sim.world import ContactParams, World

MJCF_DIR = pathlib.Path(__file__).resolve().parents[2] / "mjcf"
SHAPES = ("straight", "helix", "bezier", "ring")
OVERLAYS = ("none", "frames", "bend", "twist")
#: Default control points of the "bezier" shape (scaled to the rod length).
BEZIER_CONTROL = np.array([[0, 0, 0], [0.3, 0.5, 0], [0.6, -0.5, 0], [1.0, 0, 0],
                           [1.3, 0.4, 0], [1.6, -0.2, 0], [2.0, 0.1, 0]]) * 0.5
#: Rod colours (RGBA), cycled: warm and saturated, to stand out from the grey-blue scenes.
COLOURS = [(0.9, 0.3, 0.15, 1), (0.95, 0.7, 0.1, 1), (0.2, 0.65, 0.3, 1), (0.75, 0.2, 0.55, 1),
           (0.15, 0.55, 0.85, 1), (0.55, 0.35, 0.2, 1)]


def scene_names() -> list[str]:
    """Names of the scenes that ship in mjcf/."""
    return sorted(p.stem for p in MJCF_DIR.glob("*.xml"))


def scene_path(scene: str) -> pathlib.Path:
    """Path of a scene given by name (mjcf/NAME.xml) or by path; ValueError names the choices."""
    p = MJCF_DIR / f"{scene}.xml"
    if p.is_file():
        return p
    q = pathlib.Path(scene)
    if q.suffix == ".xml" or q.exists():
        if not q.is_file():
            raise ValueError(f"scene file {scene!r} does not exist")
        return q
    raise ValueError(f"unknown scene {scene!r}; choose one of {', '.join(scene_names())} or give an MJCF path")


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


def build_world(p: DropParams) -> World:
    """The scene with ``p.rods`` rods placed above its drop site."""
    path = scene_path(p.scene)
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as err:
        raise ValueError(f"cannot read MJCF scene {str(path)!r}: {err}") from None
    site = next((s for s in spec.sites if s.name == "drop"), None)
    centre = np.array(site.pos, dtype=float) if site is not None else np.array([0.0, 0.0, 1.0])
    spread = float(site.size[0]) if site is not None else 0.3
    world = World(spec, dt=p.dt, mass_damping=p.mass_damping, contact=ContactParams(friction=0.8))
    rng = np.random.default_rng(p.seed)
    base = rod_shape(p.shape, p.length, p.n_edges, p.control)
    ring = p.shape == "ring"
    for i in range(p.rods):
        yaw = math.pi * i / p.rods + rng.uniform(-0.2, 0.2)
        rot = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
        offset = np.array([*rng.uniform(-0.3, 0.3, size=2) * spread, 0.12 * i])
        x = base @ rot.T + centre + offset
        rod = Rod(x, p.material, closed=True, boundary=TwistBoundary("ring")) if ring else Rod(x, p.material)
        world.add_rod(rod, f"rod{i}", rgba=COLOURS[i % len(COLOURS)])
    world.compile()
    return world


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


def drop(p: DropParams, out, progress: bool = True, still=None) -> dict:
    """Simulate ``p`` and write an MP4 to ``out``; returns a summary dict.

    still: optional PNG path for the last frame (overlays included).
    The files appear only once complete (see :mod:`derods.render`).
    """
    if still is not None:
        render.check_output_path(still)
    out = render.check_output_path(out)
    world = build_world(p)
    cam_name = p.camera
    if cam_name is None and mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, "main") >= 0:
        cam_name = "main"
    paint = overlay_painter(world, p.overlay)
    frames = render.film(world, out, p.seconds, p.fps, p.width, p.height, cam_name,
                         paint=paint, progress=progress, label=f"drop {p.scene}")
    if still is not None:
        cam = render.Camera(world.model, p.width, p.height, cam_name)
        try:
            render.write_image(still, cam.render(world.data, paint))
        finally:
            cam.close()
    return {"out": str(out), "frames": frames, "sim_s": world.time, "steps": world.n_steps,
            "rods": world.rod_names, "mode": world.mode}
