"""Keyframes of a MuJoCo 3.x cable model, carried over to the model derods builds.

A 3.x keyframe's ``qpos`` and ``qvel`` are laid out for MuJoCo's jointed cable: the scene's
joints and, where each composite stood, the cable's (B_first's free or ball joint, then a
ball joint per body). derods' model has the scene's joints in the same order, then its rods'
own dofs. :func:`layout` reads the 3.x layout from the file, :func:`split` takes each key's
values apart, and :func:`apply` writes the scene's part into the compiled model's keys (the
rods start as declared; a cable part that is not the cable's initial pose is said once).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np

from . import mjcf_xml

#: (qpos, qvel) sizes by joint type.
SIZES = {"free": (7, 6), "ball": (4, 3), "slide": (1, 1), "hinge": (1, 1)}


@dataclass
class Segment:
    """One joint of the 3.x model: a scene joint (``cable`` None) or a cable's (its prefix)."""

    nq: int
    nv: int
    cable: str | None = None
    identity: bool = False  #: a cable's ball joint, at rest in the identity quaternion


def layout(root: ET.Element, classes: dict) -> list[Segment]:
    """The joints of the 3.x model in MuJoCo's order (bodies depth first in document order,
    each body's joints in document order; a composite's joints where it stands)."""
    out: list[Segment] = []

    def walk(elem: ET.Element, bodies: list):
        for child in elem:
            if child.tag == "body":
                walk(child, bodies + [child])
            elif child.tag == "frame":
                walk(child, bodies)
            elif child.tag == "freejoint":
                out.append(Segment(*SIZES["free"]))
            elif child.tag == "joint":
                attrs = mjcf_xml.resolved(child, "joint", mjcf_xml.childclass(bodies), classes)
                out.append(Segment(*SIZES.get(attrs.get("type", "hinge"), (1, 1))))
            elif child.tag == "composite" and child.get("type") == "cable":
                prefix = child.get("prefix", "")
                n = _count(child)
                initial = child.get("initial", "ball")
                if initial in ("free", "ball"):
                    out.append(Segment(*SIZES[initial], cable=prefix))
                out.extend(Segment(4, 3, cable=prefix, identity=True) for _ in range(max(n - 2, 0)))

    for world in root.findall("worldbody"):
        walk(world, [])
    return out


def _count(comp: ET.Element) -> int:
    if comp.get("vertex"):
        return len(comp.get("vertex").split()) // 3
    try:
        return int(float(comp.get("count", "1").split()[0]))
    except ValueError:
        return 0


def split(root: ET.Element, segments: list[Segment]) -> tuple[dict, list[str]]:
    """Take every key's qpos and qvel off the XML (derods' model has another layout): returns
    {key index: (scene joints' qpos values, qvel values), each a list per scene joint or None}
    and the keys whose cable part moves a cable from its initial pose, or whose sizes do not
    fit the 3.x layout (their values are dropped)."""
    nq = sum(s.nq for s in segments)
    nv = sum(s.nv for s in segments)
    out, odd = {}, []
    keys = [k for frames in root.findall("keyframe") for k in frames.findall("key")]
    for i, key in enumerate(keys):
        parts = []
        for attr, total, size in (("qpos", nq, "nq"), ("qvel", nv, "nv")):
            text = key.get(attr)
            if text is None:
                parts.append(None)
                continue
            del key.attrib[attr]
            vals = np.array([float(t) for t in text.split()])
            if len(vals) != total:
                odd.append(key.get("name") or mjcf_xml.where(key))
                parts.append(None)
                continue
            scene, at = [], 0
            for s in segments:
                n = getattr(s, size)
                v = vals[at:at + n]
                at += n
                if s.cable is None:
                    scene.append(v)
                elif attr == "qpos" and s.identity and np.max(np.abs(v - [1, 0, 0, 0])) > 1e-9:
                    odd.append(key.get("name") or mjcf_xml.where(key))
                elif attr == "qvel" and np.any(v != 0):
                    odd.append(key.get("name") or mjcf_xml.where(key))
            parts.append(scene)
        if parts != [None, None]:
            out[i] = tuple(parts)
    return out, sorted(set(odd))


def apply(model: mujoco.MjModel, keys: dict, rod_joints: set) -> bool:
    """Write each key's scene joints' values into ``model`` (compiled by derods) at those
    joints' addresses: the model's joints in order but ``rod_joints`` (ids of the rods' own
    and of their holder bodies' joints). False (nothing written) when the counts differ."""
    scene = [j for j in range(model.njnt) if j not in rod_joints]
    for k, (qpos, qvel) in keys.items():
        for vals, adr, data in ((qpos, model.jnt_qposadr, model.key_qpos), (qvel, model.jnt_dofadr, model.key_qvel)):
            if vals is None:
                continue
            if len(vals) != len(scene):
                return False
            for j, v in zip(scene, vals):
                data[k, adr[j]:adr[j] + len(v)] = v
    return True
