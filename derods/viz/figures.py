"""Still pictures: Bishop frames on Bezier rods (``derods frames``), Michell's ring
below and above its critical twist (``derods michell``)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from .. import frames, reference, shapes
from . import output, overlay, render

#: Control points [m] of the default two-segment cubic Bezier curve.
BEZIER_DEMO = np.array([
    [0.0, 0.0, 0.0], [0.3, 0.4, 0.0], [0.6, 0.5, 0.2], [1.0, 0.3, 0.2],
    [1.2, -0.3, 0.5], [1.5, 0.0, 0.0], [1.8, 0.4, 0.1],
])
ROD_RGBA = (0.9, 0.45, 0.15, 1.0)


def parse_points(text: str) -> np.ndarray:
    """Control points from "x,y,z; x,y,z; ..." [m]; ValueError says what is wrong."""
    try:
        pts = np.array([[float(v) for v in p.split(",")] for p in text.split(";") if p.strip()])
    except ValueError:
        raise ValueError(f"control points must read 'x,y,z; x,y,z; ...' [m], got {text!r}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"control points must read 'x,y,z; x,y,z; ...' [m], got {text!r}")
    return pts


def _stage(width: int, height: int) -> mujoco.MjModel:
    """An empty, lit model to draw overlays in."""
    spec = mujoco.MjSpec()
    render.add_backdrop(spec, max(width, 640), max(height, 480))
    spec.worldbody.add_light(pos=[0, 0, 5], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                             diffuse=[0.4, 0.4, 0.4])
    return spec.compile()


def _camera_for(points: np.ndarray, azimuth: float, elevation: float) -> mujoco.MjvCamera:
    cam = mujoco.MjvCamera()
    lo, hi = points.min(axis=0), points.max(axis=0)
    cam.lookat[:] = 0.5 * (lo + hi)
    cam.distance = 0.95 * float(np.linalg.norm(hi - lo)) + 0.1
    cam.azimuth, cam.elevation = azimuth, elevation
    return cam


def bezier_frames(out, control_points=BEZIER_DEMO, continuity: str = "C1", n_edges: int = 40,
                  width: int = 960, height: int = 640) -> dict:
    """Write a PNG of a Bezier rod with its Bishop frames (u pink, v green).

    The control polygon is drawn in grey with its points, the joins of the
    segments as dark spheres: across a C1 join the frames turn smoothly, across a
    C0 join they jump with the corner. Returns a summary dict.
    """
    out = output.check_output_path(out, output.IMAGE_SUFFIXES, "--out")
    p = shapes.bezier_control_points(control_points, continuity)
    x = shapes.bezier(control_points, n_edges, continuity)
    t = frames.tangents(x, False)
    u = frames.bishop_frames(x, False)
    v = np.cross(t, u)
    h = float(np.mean(np.linalg.norm(np.diff(x, axis=0), axis=1)))
    joins = shapes.bezier_eval(p, np.arange(1, (len(p) - 1) // 3))
    model = _stage(width, height)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cam = render.Camera(model, width, height, _camera_for(np.concatenate([x, p]), 110.0, -25.0))

    def draw(scene):
        for a, b in zip(p[:-1], p[1:]):
            overlay.add_segment(scene, a, b, 0.002, (0.55, 0.55, 0.6, 1.0))
        for q in p:
            overlay.add_sphere(scene, q, 0.012, (0.45, 0.45, 0.5, 1.0))
        for j in joins:
            overlay.add_sphere(scene, j, 0.022, (0.15, 0.15, 0.2, 1.0))
        overlay.add_tube(scene, x, 0.3 * h, np.tile(ROD_RGBA, (len(x) - 1, 1)))
        overlay.add_frames(scene, x, u, v, length=3.5 * h, width=0.18 * h)

    try:
        image = cam.render(data, draw)
    finally:
        cam.close()
    output.write_image(out, image)
    turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", t[1:], t[:-1]), -1, 1)))
    return {"out": str(out), "continuity": continuity, "n_edges": n_edges, "max_turn_deg": float(turn.max())}


def michell_pair(out, n_edges: int = 50, below: float = 0.9, above: float = 1.2, seconds: float = 4.0,
                 width: int = 960, height: int = 480) -> dict:
    """Write a PNG of two twisted rings after ``seconds``: at ``below`` and ``above``
    times Michell's critical twist 2 pi sqrt(3) alpha / beta (left planar, right buckled)."""
    from ..material import Material
    from ..rod import Rod
    from ..twist import TwistBoundary
    from ..sim.world import ContactParams, World

    out = output.check_output_path(out, output.IMAGE_SUFFIXES, "--out")
    mat = Material(young=1e7, radius=0.005, shear=0.5e7)  # alpha = beta
    theta_c = reference.michell_critical_twist(mat.alpha, mat.beta)
    radius = 0.2
    rings = []
    for frac, centre in ((below, -0.3), (above, 0.3)):
        x = shapes.circle(radius, n_edges, center=(centre, 0.0, 0.5))
        # Self-contact keeps a buckled ring from passing through itself (and losing its twist).
        w = World(dt=5e-3, gravity=(0.0, 0.0, 0.0), contact=ContactParams(self_collision=True))
        w.add_rod(Rod(x, mat, closed=True, natural_curvature=False,
                      boundary=TwistBoundary("ring", total_twist=frac * theta_c)), "ring")
        phi = 2 * math.pi * np.arange(n_edges) / n_edges
        xp = x.copy()
        xp[:, 2] += 1e-2 * radius * np.sin(2 * phi)
        w.set_positions("ring", xp)
        w.step(int(round(seconds / 5e-3)))
        rings.append((frac, w.positions("ring"), w.rod_state("ring")))
    model = _stage(width, height)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    allx = np.concatenate([r[1] for r in rings])
    cam = render.Camera(model, width, height, _camera_for(allx, 90.0, -35.0))

    def draw(scene):
        for frac, x, state in rings:
            m1, m2 = frames.material_frames(state.u, state.t, state.theta)
            colour = (0.2, 0.55, 0.85, 1.0) if frac < 1 else (0.9, 0.3, 0.15, 1.0)
            overlay.add_tube(scene, x, 0.012, np.tile(colour, (len(x), 1)), closed=True)
            xo = np.concatenate([x, x[:1]])
            overlay.add_frames(scene, xo, m1, m2, length=0.04, width=0.003, every=2)

    try:
        image = cam.render(data, draw)
    finally:
        cam.close()
    output.write_image(out, image)
    bend = [float(np.linalg.svd(r[1] - r[1].mean(0), compute_uv=False)[-1]) for r in rings]
    return {"out": str(out), "theta_c": theta_c, "out_of_plane": bend}
