"""A MuJoCo 3.x ``<composite type="cable">`` read as a derods rod.

What maps to what (units are the model's: m, kg, s, Pa):

- the vertices (``curve`` / ``count`` / ``size`` / ``quat``, or ``vertex``; ``offset``
  moves them) are the rod's vertices, its rest shape too unless the plugin's ``flat`` is
  "true" (then the rod is naturally straight, starting in that shape);
- the cable plugin's ``bend`` is Young's modulus E, ``twist`` the shear modulus G; with no
  plugin, the joints' ``stiffness`` k [N m/rad] between edges of mean length l gives
  E I = G J = k l, and a cable with neither is refused;
- the ``<geom>`` gives the section: a capsule or cylinder of radius ``size[0]``, or a box of
  half sizes ``size[1]`` (along the first body's y axis) and ``size[2]`` (z), read as the
  ellipse with the same bending stiffness about each axis and MuJoCo's torsion stiffness; its mass per length is
  what MuJoCo's geoms weighed (``mass`` per segment, or ``density``; a capsule's caps
  included); ``friction``, ``condim``, ``contype``, ``conaffinity``, ``solref``,
  ``solimp``, ``margin``, ``gap``, ``priority``, ``solmix`` and ``rgba`` go to the rod's
  collision flex when written (what is left to MuJoCo's defaults is left to derods');
- ``<joint kind="main">`` ``damping`` d [N m s/rad] becomes internal (Kelvin-Voigt)
  viscosity b = d l / (E I) [s]; its ``armature`` and ``frictionloss`` act on B_first's
  ball joint only (derods' vertices do not turn);
- ``initial``: "none" welds B_first to the composite's parent, "ball" hinges it there on a
  ball joint, "free" gives it a free joint; the rod's first edge is clamped to B_first and
  its last edge to B_last, a free body, both with the sites S_first, S_last MuJoCo made.

:func:`read_composite` returns a :class:`CableDecl`; :func:`holder_bodies` the XML of
B_first (in the composite's place) and B_last (under the world body).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from . import cable_geometry as geo
from .mjcf_xml import number, numbers, refuse, where, with_defaults

#: The composite attributes derods reads (and MuJoCo's skin ones, which it ignores).
COMPOSITE_ATTRS = {"type", "prefix", "count", "offset", "quat", "vertex", "initial", "curve", "size"}
IGNORED_ATTRS = {"spacing"}
#: The composite children derods reads; a skin is drawn by derods' own flex instead.
CHILDREN = {"joint", "geom", "site", "plugin", "skin"}
#: Geom attributes passed to the rod's collision flex when written.
CONTACT_ATTRS = {"friction": (1, 2, 3), "condim": 1, "contype": 1, "conaffinity": 1, "solref": 2, "solimp": (3, 5),
                 "margin": 1, "gap": 1, "priority": 1, "solmix": 1}
#: The least vertex count: the first and last edges are held, one vertex between them moves.
MIN_COUNT = 5
#: The holder bodies' own mass (and inertia) as a fraction of one segment's: the held
#: vertices, their children, carry the rod's mass.
HOLDER_MASS_FRACTION = 1e-3


@dataclass
class CableDecl:
    """A rod declared in MJCF, as :meth:`derods.World.add_rod` takes it.

    name: the rod's name. x: its vertices [m], shape (n, 3), in the frame of ``parent``
    (the body holding the declaration; "world" for the world body). material: keyword
    arguments of :class:`derods.Material`. flat: naturally straight (else ``x`` is the
    rest shape). u0: the first edge's first director, shape (3,), in ``parent``'s frame
    (None: derods' own choice). start, end: "free", "pin" or "clamp"; start_body, end_body:
    the bodies holding them (None: the world). rgba: colour or None (derods' default).
    contact: the rod's collision flex attributes written in the model. stiffness_damping:
    b [s]. vmax: the plugin's stress colour scale (None if unset). element: how messages
    name the declaration.
    """

    name: str
    x: np.ndarray
    material: dict
    flat: bool = False
    u0: np.ndarray | None = None
    start: str = "free"
    end: str = "free"
    start_body: str | None = None
    end_body: str | None = None
    rgba: tuple | None = None
    contact: dict = field(default_factory=dict)
    stiffness_damping: float = 0.0
    vmax: float | None = None
    parent: str = "world"
    element: str = ""
    #: B_last's pose in ``parent``'s frame: position [m] (3,) and quaternion (4,).
    last_pose: tuple | None = None
    #: The composite's prefix and ``initial`` (None for a flexcomp).
    prefix: str = ""
    initial: str | None = None
    #: Names of the cable's end bodies and sites the model only reads (sensors, cameras).
    read: set = field(default_factory=set)
    #: The mocap bodies riding on its ends for them (made at compile): (body name, vertex,
    #: edge, starting orientation (w, x, y, z)) each (:mod:`derods.sim.riders`).
    riders: list = field(default_factory=list)


def generated_names(prefix: str, count: int) -> dict[str, str]:
    """The names MuJoCo's composite gives its elements, each mapped to what derods does with
    it: "kept" (B_first, B_last, S_first, S_last, J_first) or "inner" (bodies B_1..,
    joints J_1.., J_last, geoms G0.., the plugin instance and skin)."""
    p = prefix
    out = {f"{p}B_first": "kept", f"{p}B_last": "kept", f"{p}S_first": "kept", f"{p}S_last": "kept",
           f"{p}J_first": "kept", f"{p}J_last": "inner", f"{p}Skin": "inner", f"composite{p}": "inner"}
    for i in range(1, count - 2):
        out[f"{p}B_{i}"] = out[f"{p}J_{i}"] = "inner"
    for i in range(count - 1):
        out[f"{p}G{i}"] = out[f"{p}Js{i}"] = "inner"
    return out


def plugin_config(comp: ET.Element, instances: dict, label: str) -> dict | None:
    """The cable plugin's config of a composite as {key: value}, or None without a plugin.

    instances: ``<extension>`` plugin instances by name (their ``<config>`` elements)."""
    plug = comp.find("plugin")
    if plug is None:
        return None
    if plug.get("instance"):
        if plug.get("instance") not in instances:
            refuse(plug, f"instance {plug.get('instance')!r} is not declared under <extension>: declare it, or "
                         "give the <config> elements here", label)
        plugin_name, configs = instances[plug.get("instance")]
    else:
        plugin_name, configs = plug.get("plugin"), plug.findall("config")
    if plugin_name != "mujoco.elasticity.cable":
        refuse(plug, f"plugin {plugin_name!r} is not the cable's: derods reads plugin=\"mujoco.elasticity.cable\"",
               label)
    return {c.get("key"): c.get("value", "") for c in configs}


def _modulus(cfg: dict, key: str, plug: ET.Element, label: str) -> float:
    text = cfg.get(key, "").strip()
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not v > 0 or not math.isfinite(v):
        what = "Young's modulus E" if key == "bend" else "the shear modulus G"
        refuse(plug, f'config key="{key}" value="{text}" must be {what} > 0 [Pa]: write e.g. '
                     f'<config key="{key}" value="1e7"/>', label)
    return v


def vertices(comp: ET.Element, label: str) -> np.ndarray:
    """The composite's vertices [m], shape (n, 3), in its parent's frame (``offset`` added)."""
    offset = numbers(comp, "offset", 3, [0, 0, 0], label, "0 0 1")
    if comp.get("vertex") is not None:
        if comp.get("count") is not None and numbers(comp, "count", (1, 2, 3), None, label)[0] > 1:
            refuse(comp, "give vertex or count, not both", label)
        v = numbers(comp, "vertex", range(3, 3 * 100000, 3), None, label, "0 0 0  0.1 0 0  0.2 0 0.05")
        x = v.reshape(-1, 3)
    else:
        count = numbers(comp, "count", 3, None, label, "41 1 1")
        if count is None or count[0] != int(count[0]) or count[1] != 1 or count[2] != 1:
            refuse(comp, f'count="{comp.get("count")}" must be "N 1 1" (a cable is one-dimensional): write e.g. '
                         'count="41 1 1"', label)
        curve = (comp.get("curve") or "s 0 0").split()
        bad = [c for c in curve if c not in geo.CURVE_SHAPES] or ([] if len(curve) <= 3 else curve[3:])
        if bad:
            refuse(comp, f'curve="{comp.get("curve")}": {bad[0]!r} is not one of {", ".join(geo.CURVE_SHAPES)} '
                         '(at most three, for x y z): write e.g. curve="s 0 0"', label)
        size = numbers(comp, "size", (1, 2, 3), [1, 0, 0], label, "1 0.1 2")
        size = np.concatenate([size, np.zeros(3 - len(size))])
        if size[0] <= 0 and "s" in curve:
            refuse(comp, f'size="{comp.get("size")}": its first number, the length along "s", must be > 0 [m]',
                   label)
        quat = numbers(comp, "quat", 4, [1, 0, 0, 0], label, "1 0 0 0")
        x = geo.curve_vertices(tuple(curve + ["0"] * (3 - len(curve))), int(count[0]), size, quat)
    if len(x) < MIN_COUNT:
        refuse(comp, f"has {len(x)} vertices; derods needs at least {MIN_COUNT} (B_first and B_last hold the first "
                     "and last edges, and a vertex between them moves): raise count", label)
    edges = np.linalg.norm(np.diff(x, axis=0), axis=1)
    if np.min(edges) <= 1e-9 * max(float(np.max(edges)), 1e-300):
        k = int(np.argmin(edges))
        refuse(comp, f"vertices {k} and {k + 1} coincide: a cable's edges need a length; move one of them", label)
    return x + offset


def contact_attrs(elem: ET.Element, shown: ET.Element, label: str | None = None) -> dict:
    """The contact attributes of :data:`CONTACT_ATTRS` written on ``elem`` (a geom with its
    defaults, or a flexcomp's ``<contact>``; ``shown`` names it in messages), as the
    collision flex takes them: integers, or float arrays (friction padded to 3 and solimp
    to 5 numbers with MuJoCo's defaults)."""
    contact = {}
    for key, n in CONTACT_ATTRS.items():
        if elem.get(key) is not None:
            vals = numbers(elem, key, n, None, label)
            contact[key] = int(vals[0]) if key in ("condim", "contype", "conaffinity", "priority") else vals
    if "friction" in contact and len(contact["friction"]) < 3:
        contact["friction"] = np.concatenate([contact["friction"], [0.005, 0.0001][len(contact["friction"]) - 1:]])
    if "solimp" in contact and len(contact["solimp"]) < 5:
        contact["solimp"] = np.concatenate([contact["solimp"], [0.5, 2.0]])
    if contact.get("condim", 3) not in (1, 3, 4, 6):
        refuse(shown, f'condim="{contact["condim"]}" must be 1, 3, 4 or 6', label)
    return contact


def read_composite(comp: ET.Element, cls: str | None, classes: dict, instances: dict, parent: str,
                   taken: set) -> CableDecl:
    """The rod a ``<composite type="cable">`` declares (see the module docstring).

    cls: the default class in force (the enclosing bodies' childclass); classes: the
    model's default classes (:func:`derods.io.mjcf_xml.default_classes`); instances: the
    ``<extension>`` plugin instances; parent: the enclosing body's name ("world" for the
    world body); taken: names already in the model (the rod's must not be).
    """
    prefix = comp.get("prefix", "")
    label = f"prefix {prefix!r}" if prefix else ""
    if comp.get("type") != "cable":
        refuse(comp, f'type="{comp.get("type")}": derods reads type="cable" composites only (MuJoCo 4 replaced '
                     'the others by flexcomp and replicate)', label)
    for key in comp.attrib:
        if key not in COMPOSITE_ATTRS and key not in IGNORED_ATTRS and not key.startswith("skin"):
            refuse(comp, f"unknown attribute {key}: a cable composite takes {', '.join(sorted(COMPOSITE_ATTRS))}",
                   label)
    for child in comp:
        if child.tag not in CHILDREN:
            refuse(child, f"<{child.tag}> is not part of a cable composite: use joint, geom, site or plugin", label)
    initial = comp.get("initial", "ball")
    if initial not in ("free", "ball", "none"):
        refuse(comp, f'initial="{initial}" must be one of free, ball, none: write e.g. initial="none"', label)
    if initial == "free" and parent != "world":
        refuse(comp, 'initial="free" needs the composite directly under <worldbody> (a free joint is top-level '
                     'only): move it, or use initial="ball" or "none"', label)
    x = vertices(comp, label)
    joints = [j for j in comp.findall("joint") if j.get("kind", "main") == "main"]
    for j in comp.findall("joint"):
        if j.get("kind", "main") != "main":
            refuse(j, f'kind="{j.get("kind")}": a cable has kind="main" joints only', label)
    joint = with_defaults(joints[0] if joints else ET.Element("joint"), "joint", cls, classes)
    gelem = comp.find("geom")
    if gelem is None:
        refuse(comp, 'has no <geom>: give one, e.g. <geom type="capsule" size="0.005"/>', label)
    geom = with_defaults(gelem, "geom", cls, classes)
    kind = geom.get("type", "sphere")
    if kind not in ("capsule", "cylinder", "box"):
        refuse(gelem, f'type="{kind}": a cable\'s geom is a capsule, cylinder or box: write e.g. type="capsule"',
               label)
    if kind == "box":
        size = numbers(geom, "size", 3, None, label, "0.01 0.02 0.002")
        if size is None or size[1] <= 0 or size[2] <= 0:
            refuse(gelem, 'a box cable\'s size must be 3 numbers with size[1], size[2] > 0 (the section\'s half '
                          'sizes [m]; size[0] is set by the edge length): write e.g. size="0 0.01 0.002"', label)
    else:
        size = numbers(geom, "size", (1, 2, 3), None, label, "0.005")
        if size is None or size[0] <= 0:
            refuse(gelem, f'a {kind} cable needs size="r" with radius r > 0 [m]: write e.g. size="0.005"', label)
    edges = np.linalg.norm(np.diff(x, axis=0), axis=1)
    length = float(edges.sum())
    if geom.get("mass") is not None:
        total = number(geom, "mass", 0.0, label, gt=0, unit="kg", example="0.01") * len(edges)
    else:
        rho = number(geom, "density", 1000.0, label, gt=0, unit="kg/m^3", example="1000")
        total = sum(geo.segment_mass(kind, size, float(le), rho) for le in edges)
    line_density = total / length
    frames = geo.body_frames(x)
    r0 = geo.quat_to_mat(frames[0])
    u0 = None
    cfg = plugin_config(comp, instances, label)
    plug = comp.find("plugin")
    stiffness = number(joint, "stiffness", 0.0, label, ge=0, unit="N m/rad")
    if cfg is not None and stiffness > 0:
        refuse(joints[0], "has stiffness besides the cable plugin: derods takes the stiffness from one of them; "
                          "drop the joint's stiffness", label)
    if kind == "box":
        # The thinner half size is the Material's radius (the collision radius). A derods rod
        # bends about its first director u0 with E pi a^3 b / 4 (a = radius, measured: a thin
        # strip with u0 across it sags as the strip would): radius lies across u0, radius2
        # along it. So u0 runs along the wider half size.
        h, w = float(size[1]), float(size[2])
        u0 = r0[:, 1] if h >= w else r0[:, 2]
        h, w = min(h, w), max(h, w)
        second = ((2 * w) ** 3 * 2 * h / 12, (2 * h) ** 3 * 2 * w / 12)
        torsion = geo.box_torsion(h, w)
    else:
        r = float(size[0])
        second = (math.pi * r**4 / 4,) * 2
        torsion = math.pi * r**4 / 2
    l_mean = length / len(edges)
    if cfg is not None:
        young, shear = _modulus(cfg, "bend", plug, label), _modulus(cfg, "twist", plug, label)
        flat = cfg.get("flat", "false").strip() == "true"
        vmax = cfg.get("vmax")
    elif stiffness > 0:
        young, shear = stiffness * l_mean / second[0], stiffness * l_mean / torsion
        if kind == "box":
            refuse(joints[0], "a box cable stiffened by joint stiffness alone is not read by derods: add the cable "
                              "plugin with bend and twist", label)
        flat, vmax = False, None
    else:
        refuse(comp, 'has neither the cable plugin nor joint stiffness, so no bending stiffness: add <plugin '
                     'plugin="mujoco.elasticity.cable"> with <config key="bend" value="E"/> and <config '
                     'key="twist" value="G"/> (Pa)', label)
    if kind == "box":
        material = {"young": young, **geo.box_as_ellipse(h, w, shear, 1.0)}
        material["density"] = line_density / (math.pi * material["radius"] * material["radius2"])
    else:
        material = {"young": young, "shear": shear, "radius": r, "density": line_density / (math.pi * r * r)}
    damping = number(joint, "damping", 0.0, label, ge=0, unit="N m s/rad")
    contact = contact_attrs(geom, gelem, label)
    rgba = None
    if geom.get("rgba") is not None:
        rgba = tuple(float(c) for c in numbers(geom, "rgba", 4, None, label, "0.8 0.2 0.1 1"))
    name = f"{prefix}cable"
    if name in taken:
        refuse(comp, f"derods names this cable's rod {name!r}, which the model already uses: rename that element "
                     "or change the prefix", label)
    vmax_v = None
    if vmax not in (None, ""):
        try:
            vmax_v = float(vmax)
        except ValueError:
            refuse(plug, f'config key="vmax" value="{vmax}" must be a number [N m] (the largest elastic moment '
                         'of the stress colours)', label)
    return CableDecl(
        name=name, x=x, material=material, flat=flat, u0=u0, rgba=rgba, contact=contact, prefix=prefix,
        initial=initial,
        stiffness_damping=damping * l_mean / (young * 0.5 * (second[0] + second[1])), vmax=vmax_v, parent=parent,
        element=where(comp, label), last_pose=(x[-2].copy(), frames[-1].copy()),
    )


def set_ends(decl: CableDecl, first_body: bool, last_body: bool) -> None:
    """How the rod's ends are held: by the bodies B_first (welded for ``initial="none"``, else
    when ``first_body``: the model refers to it) and B_last (when ``last_body``), clamping
    the end edges; else as ``initial`` says without a body (a "ball" start pinned to the
    parent, a "free" start free) and a free end. An end already held (an equality made a
    hold, :func:`derods.io.mjcf_load`) keeps its hold."""
    parent = None if decl.parent == "world" else decl.parent
    if decl.start == "free":
        if decl.initial == "none" or first_body:
            decl.start, decl.start_body = "clamp", f"{decl.prefix}B_first"
        elif decl.initial == "ball":
            decl.start, decl.start_body = "pin", parent
    if decl.end == "free" and last_body:
        decl.end, decl.end_body = "clamp", f"{decl.prefix}B_last"


def holder_bodies(comp: ET.Element, decl: CableDecl, cls: str | None, classes: dict) -> tuple[ET.Element | None,
                                                                                                ET.Element | None]:
    """The XML of B_first (for the composite's place, in its parent's frame) and B_last (for
    the world body; its pose is set once the parent's is known), those the rod's ends are
    clamped to (:func:`set_ends`; None for the others), with their joints, sites and small
    inertias (their held vertices carry the rod's mass)."""
    prefix = comp.get("prefix", "")
    initial = comp.get("initial", "ball")
    frames = geo.body_frames(decl.x)
    edges = np.linalg.norm(np.diff(decl.x, axis=0), axis=1)
    seg = decl.material["density"] * math.pi * decl.material["radius"] * decl.material.get(
        "radius2", decl.material["radius"]) * float(edges.mean())
    m = HOLDER_MASS_FRACTION * seg
    inertia = m * max(decl.material["radius"], decl.material.get("radius2", 0.0)) ** 2
    joints = [j for j in comp.findall("joint") if j.get("kind", "main") == "main"]
    joint = with_defaults(joints[0] if joints else ET.Element("joint"), "joint", cls, classes)
    selem = comp.find("site")
    site = dict(with_defaults(selem, "site", cls, classes).attrib) if selem is not None else {}
    site.setdefault("group", "3")

    def body(name, pos, quat):
        b = ET.Element("body", {"name": name, "pos": _fmt(pos), "quat": _fmt(quat)})
        ET.SubElement(b, "inertial", {"pos": "0 0 0", "mass": f"{m:.17g}", "diaginertia": _fmt([inertia] * 3)})
        return b

    first = body(f"{prefix}B_first", decl.x[0], frames[0])
    if initial == "free":
        ET.SubElement(first, "freejoint", {"name": f"{prefix}J_first"})
    elif initial == "ball":
        attrs = {"name": f"{prefix}J_first", "type": "ball"}
        for key in ("damping", "armature", "frictionloss"):
            if joint.get(key) is not None:
                attrs[key] = joint.get(key)
        ET.SubElement(first, "joint", attrs)
    ET.SubElement(first, "site", {**site, "name": f"{prefix}S_first", "pos": "0 0 0", "quat": "1 0 0 0"})
    last = body(f"{prefix}B_last", decl.x[-2], frames[-1])
    ET.SubElement(last, "freejoint")
    ET.SubElement(last, "site", {**site, "name": f"{prefix}S_last", "pos": _fmt([edges[-1], 0, 0]),
                                 "quat": "1 0 0 0"})
    return (first if decl.start_body == f"{prefix}B_first" else None,
            last if decl.end_body == f"{prefix}B_last" else None)


def _fmt(v) -> str:
    return " ".join(f"{float(c):.17g}" for c in v)
