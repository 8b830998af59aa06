"""A MuJoCo 1D ``<flexcomp>`` (MuJoCo 4's own discrete elastic rod) read as a derods rod.

Opt-in (``World(path, rods_from="flexcomp")``), so that a MuJoCo 4 user can move a flex
cable to derods without rewriting it. The points are taken where MuJoCo's compiler puts
them (any flexcomp type that makes an open chain: ``grid`` with ``count="N 1 1"``,
``direct`` with a chain of elements, ...), so ``pos``, ``quat`` and the type's own layout
are MuJoCo's. What maps to what:

- ``<elasticity>`` ``young`` E [Pa], ``shear`` G [Pa] (or E / (2 (1 + poisson)) when zero),
  ``damping`` (Rayleigh's, [s]: derods' ``stiffness_damping``); a "circle" section of the
  flex ``radius``; the rest shape is the initial one (MuJoCo keeps curvature above 1e-4
  rad, derods all of it);
- ``mass`` [kg] (the whole flexcomp's): the rod's mass per length is mass / length;
- ``<pin id="0"/>`` pins the first point to the flexcomp's parent body, ``id="0 1"``
  clamps the first edge (likewise the last one or two points for the end);
- ``<contact>`` attributes and ``rgba`` go to the rod's collision flex when written;
- the rod is named as the flexcomp, so its vertex bodies have the flexcomp's body names
  (``NAME_3``); the twist bodies (``NAME_twist_2``) do not exist in derods.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from .mjcf_cable import CableDecl, contact_attrs
from .mjcf_xml import number, numbers, refuse, where



def is_rod(elem: ET.Element) -> bool:
    """Whether a ``<flexcomp>`` is one-dimensional and not rigid (a rod derods can take)."""
    return elem.get("dim", "2") == "1" and elem.get("rigid", "false") != "true"


def pinned(elem: ET.Element) -> set[int]:
    """The pinned point ids of a flexcomp (``<pin id>`` and ``<pin range>``)."""
    out: set[int] = set()
    for pin in elem.findall("pin"):
        if pin.get("id"):
            out |= {int(float(t)) for t in pin.get("id").split()}
        if pin.get("range"):
            r = [int(float(t)) for t in pin.get("range").split()]
            for a, b in zip(r[::2], r[1::2]):
                out |= set(range(a, b + 1))
        for key in ("grid", "gridrange"):
            if pin.get(key):
                refuse(pin, f"{key}: derods reads a 1D flexcomp's pins by id or range")
    return out


def generated_names(name: str, n: int) -> dict[str, str]:
    """Names MuJoCo makes for a 1D flexcomp that derods does not keep (its twist bodies)."""
    out = {f"{name}_twist": "inner"}
    out.update({f"{name}_twist_{i}": "inner" for i in range(n)})
    return out


def read_flexcomp(elem: ET.Element, parent: str, model: mujoco.MjModel) -> CableDecl:
    """The rod a 1D ``<flexcomp>`` declares, its points [m] where ``model`` (the scene
    compiled with the flexcomp) has them, in world frame; ``parent`` names the body holding
    its pinned points ("world" for the world body)."""
    name = elem.get("name")
    if not name:
        refuse(elem, "has no name: a flexcomp needs one (derods names its rod after it)")
    if elem.get("dof", "full") != "full":
        refuse(elem, f'dof="{elem.get("dof")}": derods reads flexcomps of dof="full" (three slides per point)')
    for child in elem:
        if child.tag not in ("elasticity", "pin", "contact", "edge"):
            refuse(child, f"<{child.tag}> in a 1D flexcomp is not read by derods: remove it, or keep the flexcomp "
                          "MuJoCo's (rods_from='composite')")
    f = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_FLEX, name)
    adr, nvert = int(model.flex_vertadr[f]), int(model.flex_vertnum[f])
    edges = model.flex_elem[model.flex_elemdataadr[f]:model.flex_elemdataadr[f] + 2 * model.flex_elemnum[f]]
    chain = np.column_stack([np.arange(nvert - 1), np.arange(1, nvert)]).ravel()
    if len(edges) != len(chain) or np.any(np.asarray(edges) != chain):
        refuse(elem, "is not an open chain of its points in order (0-1, 1-2, ...): derods reads open 1D "
                     "flexcomps; keep this one MuJoCo's (rods_from='composite')")
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_flex(model, data)
    x = np.array(data.flexvert_xpos[adr:adr + nvert])
    el = elem.find("elasticity")
    el = el if el is not None else ET.Element("elasticity")
    young = number(el, "young", 0.0, ge=0, unit="Pa", example="1e7")
    if young <= 0:
        refuse(el, "young must be > 0 [Pa] for derods to bend the rod: write e.g. <elasticity young=\"1e7\"/>")
    if el.get("section", "circle") != "circle":
        refuse(el, f'section="{el.get("section")}": derods reads circle sections of flexcomps; a box-section rod '
                   'reads as a composite cable with a box geom')
    poisson = number(el, "poisson", 0.0, ge=0, example="0.3")
    shear = number(el, "shear", 0.0, ge=0, unit="Pa") or young / (2.0 * (1.0 + poisson))
    radius = float(model.flex_radius[f])
    length = float(np.linalg.norm(np.diff(x, axis=0), axis=1).sum())
    mass = number(elem, "mass", 1.0, gt=0, unit="kg", example="0.1")
    pins = pinned(elem)
    ends = []
    for a, b in ((0, 1), (nvert - 1, nvert - 2)):
        ends.append("clamp" if {a, b} <= pins else "pin" if a in pins else "free")
    held = {"clamp": {0, 1}, "pin": {0}, "free": set()}[ends[0]]
    held |= {"clamp": {nvert - 1, nvert - 2}, "pin": {nvert - 1}, "free": set()}[ends[1]]
    if pins - held:
        refuse(elem, f"pins point(s) {sorted(pins - held)}: derods holds a rod by its ends only (pin id 0, or 0 1 "
                     "to clamp; the last one or two points likewise)")
    holder = None if parent == "world" else parent
    celem = elem.find("contact")
    contact = {} if celem is None else contact_attrs(celem, celem)
    rgba = None if elem.get("rgba") is None else tuple(float(c) for c in numbers(elem, "rgba", 4))
    return CableDecl(
        name=name, x=x, material={"young": young, "shear": shear, "radius": radius,
                                  "density": mass / length / (math.pi * radius * radius)},
        start=ends[0], end=ends[1], start_body=holder if ends[0] != "free" else None,
        end_body=holder if ends[1] != "free" else None, rgba=rgba, contact=contact,
        stiffness_damping=number(el, "damping", 0.0, ge=0, unit="s"), parent="world", element=where(elem))
