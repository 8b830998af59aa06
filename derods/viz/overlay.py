"""Drawing on top of a rendered scene: frame arrows, strain colouring, rods as lines.

Functions here add geoms to a ``mujoco.MjvScene`` (pass them to
:meth:`derods.viz.render.Camera.render` as the scene callback). Colours follow the
DER paper's figures: the first director (normal) pink, the second (binormal)
green.
"""

from __future__ import annotations

import mujoco
import numpy as np

PINK = (0.95, 0.35, 0.65, 1.0)
GREEN = (0.2, 0.75, 0.3, 1.0)


def _add(scene, geom_type, size, rgba) -> object:
    if scene.ngeom >= scene.maxgeom:
        raise ValueError(
            f"the scene holds at most {scene.maxgeom} geoms; draw fewer overlays (e.g. every k-th frame)"
        )
    g = scene.geoms[scene.ngeom]
    mujoco.mjv_initGeom(g, geom_type, np.asarray(size, float), np.zeros(3), np.eye(3).ravel(),
                        np.asarray(rgba, np.float32))
    scene.ngeom += 1
    return g


def add_segment(scene, a, b, width: float, rgba, geom_type=mujoco.mjtGeom.mjGEOM_CAPSULE) -> None:
    """A capsule (or arrow, cylinder, line) from point a to point b [m], of radius ``width`` [m]."""
    g = _add(scene, geom_type, [0.0, 0.0, 0.0], rgba)
    mujoco.mjv_connector(g, geom_type, width, np.asarray(a, float), np.asarray(b, float))


def add_sphere(scene, p, radius: float, rgba) -> None:
    """A sphere of ``radius`` [m] at point p [m]."""
    g = _add(scene, mujoco.mjtGeom.mjGEOM_SPHERE, [radius, radius, radius], rgba)
    g.pos[:] = np.asarray(p, float)


def add_frames(scene, x: np.ndarray, d1: np.ndarray, d2: np.ndarray, length: float, width: float,
               every: int = 1, rgba1=PINK, rgba2=GREEN) -> None:
    """Arrows of two directors at every ``every``-th edge midpoint of an open rod.

    x: vertex positions [m], shape (n_vertices, 3); d1, d2: unit directors per edge,
    shape (n_edges, 3) (Bishop u, v or material m1, m2). length, width: arrow size [m].
    """
    mid = 0.5 * (x[1:] + x[:-1])
    for j in range(0, len(mid), every):
        add_segment(scene, mid[j], mid[j] + length * d1[j], width, rgba1, mujoco.mjtGeom.mjGEOM_ARROW)
        add_segment(scene, mid[j], mid[j] + length * d2[j], width, rgba2, mujoco.mjtGeom.mjGEOM_ARROW)


def strain_colours(values: np.ndarray, vmax: float | None = None) -> np.ndarray:
    """RGBA per value on a blue (0) to yellow to red (vmax) scale, shape (n, 4)."""
    v = np.abs(np.asarray(values, float))
    top = vmax if vmax else (v.max() if v.max() > 0 else 1.0)
    s = np.clip(v / top, 0.0, 1.0)[:, None]
    low, mid, high = np.array([0.2, 0.4, 0.9]), np.array([0.95, 0.85, 0.2]), np.array([0.9, 0.15, 0.1])
    rgb = np.where(s < 0.5, low + (mid - low) * (2 * s), mid + (high - mid) * (2 * s - 1))
    return np.concatenate([rgb, np.ones((len(v), 1))], axis=1)


def jet_colours(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGBA per value (n,) on the jet scale MuJoCo's cable plugin colours stress with:
    blue (0), cyan, yellow, red (vmax and above), shape (n, 4)."""
    s = np.clip(np.asarray(values, dtype=float) / vmax, 0.0, 1.0)
    r = np.clip(4.0 * s - 2.0, 0.0, 1.0)
    g = np.clip(np.minimum(4.0 * s, 4.0 - 4.0 * s), 0.0, 1.0)
    b = np.clip(2.0 - 4.0 * s, 0.0, 1.0)
    return np.stack([r, g, b, np.ones_like(s)], axis=1)


def internal_moment(rod, x: np.ndarray, state) -> np.ndarray:
    """The elastic moment's magnitude per edge [N m], shape (n_edges,), what MuJoCo's cable
    plugin colours by (the moment at its joints, averaged onto the segment): at each joint
    |(B1 dw1, B2 dw2)| and G J dm over its Voronoi length l_k / 2 (dw the material curvature
    less the rest's, dm the twist less the rest's; Bergou et al. 2008), combined as a vector,
    then averaged onto the joint's edges. The curvature is the rod's measure of bending
    (``rod.bending``), the one its rest curvatures and its energy take."""
    from ..frames import material_curvatures, material_frames
    from ..geometry import JointGeometry, curvature, edges, joint_pairs

    m1, m2 = material_frames(state.u, state.t, state.theta)
    kb = curvature(JointGeometry(*joint_pairs(edges(x, rod.closed), rod.closed)), rod.bending).kb
    w = material_curvatures(kb, m1, m2, rod.closed)
    if rod.rest_curvature is not None:
        w = w - rod.rest_curvature
    w = w.mean(axis=-2)  # the joint's two edges' frames
    b1, b2 = rod.material.bend_stiffness
    moment = np.hypot(b1 * w[:, 0], b2 * w[:, 1])
    if "twist" in rod.active_terms:
        moment = np.hypot(moment, rod.material.beta * _twist_per_joint(rod, state))
    return _onto_edges(moment / (0.5 * rod.vlen), rod.closed)


def _twist_per_joint(rod, state) -> np.ndarray:
    """|m_k - mbar_k| per joint [rad]: the material frame's turn across it, less the rest's."""
    from ..frames import reference_twist
    from ..geometry import joint_pairs

    th_a, th_b = joint_pairs(state.theta[..., None], rod.closed)
    m = th_b[..., 0] - th_a[..., 0] + reference_twist(state.u, state.t, rod.closed)
    return np.abs(m + rod.boundary.seam_offset(len(m)) - rod.mbar)


def _onto_edges(per_joint: np.ndarray, closed: bool) -> np.ndarray:
    """Values per joint averaged onto edges (an open rod's end edges get half of one joint's)."""
    if closed:
        return 0.5 * (per_joint + np.roll(per_joint, -1))
    out = np.zeros(len(per_joint) + 1)
    out[:-1] += 0.5 * per_joint
    out[1:] += 0.5 * per_joint
    return out


def add_tube(scene, x: np.ndarray, radius: float, rgba_per_edge: np.ndarray, closed: bool = False) -> None:
    """The rod as capsules, one per edge, coloured per edge (e.g. by :func:`strain_colours`)."""
    n = len(x) if closed else len(x) - 1
    for j in range(n):
        add_segment(scene, x[j], x[(j + 1) % len(x)], radius, rgba_per_edge[j])


def bending_strain(x: np.ndarray, closed: bool) -> np.ndarray:
    """Curvature per edge [1/m], shape (n_edges,): the mean over the edge's joints of
    |kb| / (mean length of the joint's two edges). Times the radius it is the bending strain."""
    from ..geometry import curvature_binormal, edges, norm

    kb = norm(curvature_binormal(x, closed))
    h = norm(edges(x, closed))
    k_joint = kb / (0.5 * (h[:-1] + h[1:])) if not closed else kb / (0.5 * (np.roll(h, 1) + h))
    if closed:
        return 0.5 * (k_joint + np.roll(k_joint, -1))
    out = np.zeros(len(h))
    out[:-1] += 0.5 * k_joint
    out[1:] += 0.5 * k_joint
    return out


def twisting_strain(rod, state) -> np.ndarray:
    """Twist rate per edge [rad/m], shape (n_edges,): m_k / (l_k / 2) at the joints
    (the material frame's turn per Voronoi length), averaged onto edges. Times the
    radius it is the shear strain of twisting."""
    return _onto_edges(_twist_per_joint(rod, state) / (0.5 * rod.vlen), rod.closed)


def rod_lines(world, width: float = 2.0):
    """A scene callback that draws every rod of ``world`` as lines of ``width`` [pixels],
    one per edge, in its flex's colour: for many thin rods (hair) about ten times cheaper
    to draw than MuJoCo's flexes (1000 strands x 31 edges, 960 x 540, software GL: 0.4 s
    a frame against 5.3 s). Use with a :class:`derods.viz.render.View` of
    ``draw_flexes=False`` and room for :func:`n_edges` more geoms."""
    model = world.model
    off = world.vertex_offsets
    first, second, colour = [], [], []
    for i, rod in enumerate(world.rods):
        j = np.arange(rod.n_edges)
        first.append(off[i] + j)
        second.append(off[i] + (j + 1) % rod.n_vertices)
        fid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, world.rod_names[i])
        colour.append(np.repeat(model.flex_rgba[fid][None], rod.n_edges, axis=0))
    first, second = np.concatenate(first), np.concatenate(second)
    colour = np.concatenate(colour).astype(np.float32)
    zero3, eye9 = np.zeros(3), np.eye(3).ravel()
    line = mujoco.mjtGeom.mjGEOM_LINE

    def paint(scene):
        x = world.all_positions()
        n0 = scene.ngeom
        k_max = min(len(first), scene.maxgeom - n0)
        for k in range(k_max):
            g = scene.geoms[n0 + k]
            mujoco.mjv_initGeom(g, line, zero3, zero3, eye9, colour[k])
            mujoco.mjv_connector(g, line, width, x[first[k]], x[second[k]])
        scene.ngeom = n0 + k_max

    return paint


def n_edges(world) -> int:
    """Edges of every rod of ``world`` (the geoms :func:`rod_lines` adds)."""
    return int(sum(rod.n_edges for rod in world.rods))
