"""The MuJoCo scene drawn in the editor's page: its static geoms as viser primitives.

The page draws the rod itself (strain colours, frames, grab points); what it needs of the
scene is the still geometry the rod falls onto, once.
"""

from __future__ import annotations

import mujoco
import numpy as np


def draw_static_geoms(scene, mjcf_path: str) -> None:
    """Add the static, visible geoms of the MJCF at ``mjcf_path`` to a viser scene
    (``server.scene``) under /scene: boxes, spheres, cylinders (capsules as cylinders),
    meshes, and planes as grids. Geoms of bodies with dofs are left out."""
    m = mujoco.MjModel.from_xml_path(mjcf_path)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for g in range(m.ngeom):
        if m.body_dofnum[m.geom_bodyid[g]] or m.geom_rgba[g, 3] == 0:
            continue
        pos, size = d.geom_xpos[g], m.geom_size[g]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.geom_xmat[g])
        rgba = m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g]
        rgb = tuple(int(255 * c) for c in rgba[:3])
        name, kind = f"/scene/geom_{g}", m.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_PLANE:
            scene.add_grid(name, width=2 * size[0] or 8.0, height=2 * size[1] or 8.0, position=pos, wxyz=quat)
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            scene.add_box(name, rgb, tuple(2 * size), position=pos, wxyz=quat)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            scene.add_icosphere(name, radius=float(size[0]), color=rgb, position=pos)
        elif kind in (mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_CAPSULE):
            scene.add_cylinder(name, radius=float(size[0]), height=float(2 * size[1]), color=rgb, position=pos,
                               wxyz=quat)
        elif kind == mujoco.mjtGeom.mjGEOM_MESH:
            mid = m.geom_dataid[g]
            v0, nv = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            f0, nf = m.mesh_faceadr[mid], m.mesh_facenum[mid]
            scene.add_mesh_simple(name, m.mesh_vert[v0:v0 + nv], m.mesh_face[f0:f0 + nf], color=rgb, position=pos,
                                  wxyz=quat)
