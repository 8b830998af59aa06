"""A MuJoCo model file with rods declared in it, read into a scene and derods rods.

:func:`load` reads the file as XML; every ``<composite type="cable">`` (and, with
``rods_from="flexcomp"``, every 1D ``<flexcomp>``) becomes a :class:`CableDecl`, and the
rest is compiled by MuJoCo's own parser (``mujoco.MjSpec.from_string``). A cable
composite leaves behind the bodies and sites models refer to: ``B_first`` in its place
(welded, on a ball joint or free, as its ``initial`` says) with ``S_first``, and
``B_last``, a free body, with ``S_last``; the rod's end edges are clamped to them, so an
equality, actuator, sensor, contact exclude or tendon naming them keeps working. A
reference to what the rod replaced (an inner body ``B_3``, a geom ``G5``, a joint
``J_2``) is refused in one line. :func:`add_rods` puts the declared rods into a
:class:`derods.World`. A file with nothing to convert is read by ``MjSpec.from_file`` as
before.
"""

from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from .. import validation
from ..sim.exclusion import ExcludedPair
from ..sim.riders import Rider, Riders
from . import cable_geometry as geo
from . import mjcf_cable, mjcf_equality, mjcf_flexcomp, mjcf_keys, mjcf_xml
from .mjcf_cable import CableDecl

#: What World's ``rods_from`` takes: cable composites only (always read: MuJoCo 4 cannot),
#: or 1D flexcomps too.
RODS_FROM = ("composite", "flexcomp")
#: Attributes that name elements rather than refer to them.
_NAMING = {"name", "class", "childclass", "prefix"}


def check_rods_from(scene, rods_from) -> None:
    """Refuse a ``rods_from`` World cannot honour: an unknown one, or "flexcomp" with a scene
    that is not a file (a spec's flexcomps are already MuJoCo's bodies)."""
    validation.choice("rods_from", rods_from, RODS_FROM)
    if rods_from == "flexcomp" and (scene is None or isinstance(scene, mujoco.MjSpec)):
        raise validation.InvalidInputError("rods_from='flexcomp' reads the flexcomps of a scene file: pass the "
                                           "file's path as the scene")


def load(path: str, rods_from: str = "composite") -> tuple[mujoco.MjSpec, list[CableDecl]]:
    """The scene of the MJCF file ``path`` and the rods it declares (vertices in world frame)."""
    validation.choice("rods_from", rods_from, RODS_FROM)
    mjcf_xml.forget()
    root = mjcf_xml.read(path)
    world = root.find("worldbody")
    comps = [] if world is None else list(world.iter("composite"))
    flexes = [] if world is None or rods_from != "flexcomp" else [
        f for f in world.iter("flexcomp") if mjcf_flexcomp.is_rod(f)]
    if not comps and not flexes:
        try:
            return mujoco.MjSpec.from_file(path), Declared()
        except Exception as err:  # MuJoCo raises ValueError with its parser message
            raise validation.InvalidInputError(f"cannot read MJCF scene {path!r}: {err}") from None
    classes = mjcf_xml.default_classes(root)
    segments = mjcf_keys.layout(root, classes)  # (before the composites leave the tree)
    instances = _plugin_instances(root)
    taken = {e.get("name") for e in root.iter() if e.get("name")}
    decls, inner, found, placed = [], {}, [], []

    def walk(elem: ET.Element, bodies: list, parent: str | None):
        for child in list(elem):
            if child.tag == "body":
                walk(child, bodies + [child], child.get("name"))
            elif child.tag == "frame":
                if any(c.tag in ("composite", "flexcomp") for c in child.iter()):
                    mjcf_xml.refuse(child, "holds a composite or flexcomp: derods reads them directly in a body or "
                                           "the world body; move it out of the frame")
            elif child.tag == "composite":
                prefix = child.get("prefix", "")
                if any(d.prefix == prefix and d.initial is not None for d in decls):
                    mjcf_xml.refuse(child, f"has the prefix {prefix!r} of another cable composite: give each its own "
                                           "prefix (their B_first, B_last, ... would clash)",
                                    f"prefix {prefix!r}" if prefix else None)
                if bodies and not parent:  # the rod's vertices are placed from its parent's pose, found by name
                    parent = f"{child.get('prefix', '')}cable_parent"
                    bodies[-1].set("name", parent)
                cls = mjcf_xml.childclass(bodies)
                decl = mjcf_cable.read_composite(child, cls, classes, instances, parent if bodies else "world",
                                                 taken)
                placed.append((elem, child, cls, decl))
                decls.append(decl)
                taken.add(decl.name)
                inner.update({k: (decl.element, v) for k, v in
                              mjcf_cable.generated_names(child.get("prefix", ""), len(decl.x)).items()})
            elif child.tag == "flexcomp" and child in flexes:
                if bodies and not parent and mjcf_flexcomp.pinned(child):
                    mjcf_xml.refuse(child, "is pinned to an unnamed body: name the body so the rod's held ends "
                                           "can ride on it")
                found.append((elem, child, "world" if not bodies else parent))

    walk(world, [], None)
    _check_references(root, inner)
    held_by = mjcf_equality.to_holds(root, decls)
    for elem, comp, cls, decl in placed:
        elem.remove(comp)  # (references are looked for outside the composites)
    refs = _referenced(root, decls)
    for elem, comp, cls, decl in placed:
        mjcf_cable.set_ends(decl, *refs[decl.name])
        first, last = mjcf_cable.holder_bodies(comp, decl, cls, classes)
        if first is not None:
            elem.append(first)
        if last is not None:
            world.append(last)
        made = {e.get("name") for b in (first, last) if b is not None for e in b.iter()}
        decl.read -= made
        for name in sorted(decl.read):  # placeholders, moved onto the rod's vertices at compile
            world.append(ET.Element("site" if "S_" in name[len(decl.prefix):] else "body", {"name": name}))
    if held_by:
        warnings.warn("; ".join(held_by), validation.SceneWarning, stacklevel=3)
    _drop_cable_plugins(root)
    keys = _keyframes(root, segments, bool(found))
    _absolute_dirs(root, os.path.dirname(os.path.abspath(path)))
    if found:
        # The flexcomps' points where MuJoCo's compiler puts them, then the scene without them.
        option = root.find("option")
        integrator = None if option is None else option.get("integrator")
        if option is not None:
            option.set("integrator", "Euler")  # (MuJoCo compiles flex elasticity for Euler or discrete)
        model = _compile(_spec(root, path), path)
        if option is not None and integrator is not None:
            option.set("integrator", integrator)
        if integrator is not None and integrator.lower() == "discrete":
            option.set("integrator", "implicitfast")
            warnings.warn(f"{path}: integrator 'discrete' (MuJoCo's for its own rods) is now 'implicitfast', "
                          "which derods' rods step with", validation.SceneWarning, stacklevel=3)
        for holder, elem, parent in found:
            decls.append(mjcf_flexcomp.read_flexcomp(elem, parent, model))
            inner.update({k: (mjcf_xml.where(elem), v) for k, v in
                          mjcf_flexcomp.generated_names(elem.get("name"), len(decls[-1].x)).items()})
            holder.remove(elem)
    _check_references(root, inner)
    spec = _spec(root, path)
    _to_world(spec, decls)
    return spec, Declared(decls, keys=keys, excludes=_excluded(root, decls))


class Declared(list):
    """The rods a file declares (:class:`CableDecl`, in order), and its keyframes' values for
    the scene's joints (:mod:`derods.io.mjcf_keys`), written into the compiled model by
    :func:`finish_model`."""

    def __init__(self, decls=(), keys=None, excludes=()):
        super().__init__(decls)
        self.keys = keys or {}
        #: Contact excludes naming a cable's B_first or B_last, as the rods' end edges'
        #: (:class:`derods.sim.exclusion.ExcludedPair`; World applies them).
        self.excludes = list(excludes)


def _excluded(root: ET.Element, decls: list[CableDecl]) -> list[ExcludedPair]:
    """The pairs of a file's ``<contact><exclude>`` elements that name a cable's ``B_first``
    or ``B_last``: in MuJoCo 3.x the cable's first or last segment, here the rod's first or
    last edge, kept from colliding with the other body (or the other cable's end edge)."""
    ends = {}
    for d in decls:
        if d.initial is not None:
            ends[f"{d.prefix}B_first"] = (d.name, 0)
            ends[f"{d.prefix}B_last"] = (d.name, len(d.x) - 2)
    out = []
    for contact in root.findall("contact"):
        for ex in contact.findall("exclude"):
            a, b = ex.get("body1"), ex.get("body2")
            if a not in ends and b in ends:
                a, b = b, a
            if a not in ends:
                continue
            rod, edge = ends[a]
            if b in ends:
                out.append(ExcludedPair(rod, (edge,), other_rod=ends[b][0], other_elements=(ends[b][1],)))
            else:
                out.append(ExcludedPair(rod, (edge,), body=b))
    return out


def _spec(root: ET.Element, path: str) -> mujoco.MjSpec:
    try:
        return mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    except Exception as err:
        raise validation.InvalidInputError(f"cannot read MJCF scene {path!r}: {err}") from None


def _compile(spec: mujoco.MjSpec, path: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as err:
        raise validation.InvalidInputError(f"cannot compile MJCF scene {path!r}: {err}") from None


def _plugin_instances(root: ET.Element) -> dict:
    """``<extension>`` plugin instances by name: (plugin name, their config elements)."""
    out = {}
    for ext in root.findall("extension"):
        for plug in ext.findall("plugin"):
            for inst in plug.findall("instance"):
                out[inst.get("name")] = (plug.get("plugin"), inst.findall("config"))
    return out


def _drop_cable_plugins(root: ET.Element) -> None:
    """Remove the cable plugin's declarations (MuJoCo 4 has no such plugin; derods replaces it)."""
    for ext in root.findall("extension"):
        for plug in ext.findall("plugin"):
            if plug.get("plugin") == "mujoco.elasticity.cable":
                ext.remove(plug)
        if len(ext) == 0:
            root.remove(ext)


def _check_references(root: ET.Element, inner: dict) -> None:
    """Refuse a reference to an element a cable composite made that derods does not keep."""
    if not inner:
        return
    for elem in root.iter():
        if elem.tag == "default":
            continue
        for key, value in elem.attrib.items():
            if key in _NAMING:
                continue
            for token in value.split():
                kind = inner.get(token)
                if kind is not None and kind[1] == "inner":
                    mjcf_xml.refuse(elem, f'{key}="{value}" refers to {token!r}, which {kind[0]} made and derods '
                                          "replaces by a rod: refer to B_first, B_last, S_first or S_last (the "
                                          "rod's end edges are clamped to them) instead")


#: Elements whose references only read a body or site (no force through it).
_READERS = {"camera", "light", "exclude", "key"}


def _referenced(root: ET.Element, decls: list[CableDecl]) -> dict[str, tuple[bool, bool]]:
    """Per cable rod, whether the model (outside the composites) acts through its start's
    B_first, S_first or J_first and its end's B_last or S_last (an equality, actuator or
    tendon naming them: they need bodies that hold the rod's end edges), and notes in
    ``decl.read`` the names only read (sensors, cameras, lights, excludes, keyframes)."""
    names = {}
    for d in decls:
        if d.initial is not None:
            p = d.prefix
            names.update({f"{p}B_first": (d, 0), f"{p}S_first": (d, 0), f"{p}J_first": (d, 0),
                          f"{p}B_last": (d, 1), f"{p}S_last": (d, 1)})
    out = {d.name: [False, False] for d in decls}

    def walk(elem: ET.Element, reading: bool):
        if elem.tag == "default":
            return
        reading = reading or elem.tag in _READERS or elem.tag == "sensor"
        for key, value in elem.attrib.items():
            if key not in _NAMING:
                for token in value.split():
                    if token in names:
                        d, k = names[token]
                        if reading:
                            d.read.add(token)
                        else:
                            out[d.name][k] = True
        for child in elem:
            walk(child, reading)

    walk(root, False)
    return {k: tuple(v) for k, v in out.items()}


def _keyframes(root: ET.Element, segments: list, flexcomps: bool) -> dict:
    """Keyframes keep their time, ctrl, act and mocap poses, and their qpos and qvel of the
    scene's joints (laid out for MuJoCo's jointed cable, they are taken apart,
    :mod:`derods.io.mjcf_keys`); a cable's part is dropped, said where it is not the cable at
    rest. With flexcomps made rods, qpos and qvel are dropped whole (said)."""
    if flexcomps:
        dropped = []
        for frames in root.findall("keyframe"):
            for key in frames.findall("key"):
                for attr in ("qpos", "qvel"):
                    if key.get(attr) is not None:
                        del key.attrib[attr]
                        dropped.append(key.get("name") or mjcf_xml.where(key))
        if dropped:
            warnings.warn(f"keyframes {sorted(set(dropped))}: their qpos and qvel are dropped (laid out for "
                          "MuJoCo's flexcomps; the rods start as declared)", validation.SceneWarning, stacklevel=4)
        return {}
    keys, odd = mjcf_keys.split(root, segments)
    if odd:
        warnings.warn(f"keyframes {odd}: their cables' joint values (MuJoCo's jointed cable) are dropped, the rods "
                      "start as declared; the scene's joints, time, ctrl, act and mocap poses are kept",
                      validation.SceneWarning, stacklevel=4)
    return keys


def _absolute_dirs(root: ET.Element, folder: str) -> None:
    """Make the compiler's asset folders absolute: the model is compiled from a string."""
    comp = root.find("compiler")
    if comp is None:
        comp = ET.Element("compiler")
        root.insert(0, comp)
    keys = ("meshdir", "texturedir", "assetdir")
    if not any(comp.get(k) for k in keys):
        comp.set("assetdir", folder)
    for k in keys:
        if comp.get(k) and not os.path.isabs(comp.get(k)):
            comp.set(k, os.path.join(folder, comp.get(k)))


def _to_world(spec: mujoco.MjSpec, decls: list[CableDecl]) -> None:
    """Put each declared rod's vertices and first director in world frame, and each B_last
    where its rod's last edge starts, from the compiled pose of the parent body."""
    moved = [d for d in decls if d.parent != "world"]
    if moved:
        model = _compile(spec, "with its rods' holders")
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
    for d in decls:
        if d.parent == "world":
            p, rot = np.zeros(3), np.eye(3)
        else:
            b = model.body(d.parent).id
            p, rot = data.xpos[b].copy(), data.xmat[b].reshape(3, 3).copy()
        if d.last_pose is not None and d.end_body == f"{d.prefix}B_last":
            pos, quat = d.last_pose
            body = spec.body(d.end_body)
            body.pos = p + rot @ pos
            q = np.zeros(4)
            mujoco.mju_mat2Quat(q, (rot @ geo.quat_to_mat(quat)).ravel())
            body.quat = q
        d.x = d.x @ rot.T + p
        if d.u0 is not None:
            d.u0 = rot @ d.u0


def add_rods(world, decls: list[CableDecl]) -> None:
    """Add the declared rods to ``world`` (a :class:`derods.World` not yet compiled): each
    with its material, ends and colour (what else they need is added at compile,
    :func:`finish_spec`); their internal viscosity, the largest, as the world's
    ``stiffness_damping`` when the world was given none."""
    from ..rod import Material, Rod

    for d in decls:
        rod = Rod(d.x, Material(**d.material), u0=d.u0, natural_curvature=not d.flat)
        kw = {} if d.rgba is None else {"rgba": d.rgba}
        world.add_rod(rod, d.name, start=d.start, end=d.end, x=d.x, start_body=d.start_body, end_body=d.end_body,
                      **kw)
    damping = max((d.stiffness_damping for d in decls), default=0.0)
    if world.stiffness_damping == 0.0 and damping > 0.0:
        world.stiffness_damping = damping


def finish_model(model: mujoco.MjModel, decls: list[CableDecl]) -> None:
    """Write the declared keyframes' scene-joint values into the compiled ``model`` (World.compile
    calls it): the joints of the rods' vertex bodies and of B_first / B_last are the rods'."""
    keys = getattr(decls, "keys", None)
    if not keys:
        return
    rod_bodies = {f"{d.prefix}B_first" for d in decls} | {f"{d.prefix}B_last" for d in decls}
    rod_bodies |= {f"{d.name}_{i}" for d in decls for i in range(len(d.x))}
    rod_joints = {j for j in range(model.njnt) if model.body(int(model.jnt_bodyid[j])).name in rod_bodies}
    if not mjcf_keys.apply(model, keys, rod_joints):
        warnings.warn("keyframes: the scene's joints differ from the file's in number; their qpos and qvel are not "
                      "carried over", validation.SceneWarning, stacklevel=3)


def finish_spec(spec: mujoco.MjSpec, decls: list[CableDecl]) -> None:
    """What the declared rods need once their bodies are in ``spec`` (World.compile calls it
    after adding the rods): each collision flex's written contact attributes, and the
    bodies and sites of a cable's ends that the model only reads (a sensor, a camera's
    target): B_first / B_last ride on the end edges' first vertices and S_first / S_last sit
    on the end vertices, turned as the cable's first and last bodies were at the start."""
    for d in decls:
        flex = spec.flex(d.name)
        for key, value in d.contact.items():
            setattr(flex, key, np.asarray(value, dtype=float) if isinstance(value, np.ndarray) else value)
        if d.initial is None or not d.read:
            continue
        frames = geo.body_frames(d.x)
        n, p = len(d.x), d.prefix
        for name, vertex, edge, quat, site in ((f"{p}B_first", 0, 0, frames[0], False),
                                               (f"{p}S_first", 0, 0, frames[0], True),
                                               (f"{p}B_last", n - 2, n - 2, frames[-1], False),
                                               (f"{p}S_last", n - 1, n - 2, frames[-1], True)):
            if name not in d.read:
                continue
            spec.delete(spec.site(name) if site else spec.body(name))
            # a mocap body derods poses on the vertex every step, turned with the edge (derods.sim.riders)
            body = spec.worldbody.add_body(name=f"{name}__rides" if site else name, mocap=True, pos=d.x[vertex],
                                           quat=quat)
            if site:
                body.add_site(name=name, group=3, size=[d.material["radius"], 0, 0])
            d.riders.append((body.name, vertex, edge, np.asarray(quat, dtype=float)))
    riding = [(d.x[v], q) for d in decls for _, v, _, q in d.riders]
    for key in spec.keys:  # a keyframe's mocap poses cover the riders too, where it sets any
        if len(key.mpos):
            key.mpos = np.concatenate([np.asarray(key.mpos, dtype=float)] + [x for x, _ in riding])
            key.mquat = np.concatenate([np.asarray(key.mquat, dtype=float)] + [q for _, q in riding])


def riders(model: mujoco.MjModel, decls: list[CableDecl], layout, rods, frames) -> Riders:
    """The riding bodies :func:`finish_spec` made, for the compiled ``model`` (World.compile
    gives them to the step): each on its vertex and edge of the world's flat arrays
    (``layout``, ``rods``), turned from the rods' starting ``frames``."""
    out = []
    for d in decls:
        i = layout.names.index(d.name) if d.riders else -1
        for name, vertex, edge, quat in d.riders:
            e = int(rods.e_off[i]) + edge
            f0 = Riders.frame(frames.u[e:e + 1], frames.t[e:e + 1], frames.theta[e:e + 1])[0]
            r0 = np.zeros(9)
            mujoco.mju_quat2Mat(r0, quat)
            v0 = int(layout.v_off[i])
            out.append(Rider(int(model.body_mocapid[model.body(name).id]), v0 + vertex, e, f0.T @ r0.reshape(3, 3),
                             (v0 + edge, v0 + edge + 1)))
    return Riders(out)
