"""Equalities that tie a cable's end to a body, read as derods holds.

In MuJoCo 3.x a ``<connect>`` from ``B_last`` (at the cable's end point) to a body, or a
``<weld>`` of ``B_first`` / ``B_last`` to one, fastens the cable's end to it through a
soft constraint. derods holds the end there instead: the connect pins the end vertex to
the body, the weld clamps the end edge to it (rigidly: the equality's ``solref`` and
``solimp`` no longer apply), solved with the rods when the body has dofs. This is exact
where MuJoCo's was soft, and needs no body of the cable's own at that end.

An equality is read this way when it is active, names ``B_first`` or ``B_last`` as
``body1`` (a connect's ``anchor``, in that body's frame, at the cable's end point: the
origin of B_first, or the far end of B_last's edge), the other body is a named body or
the world (not another cable's), and that end is not held already; a weld also needs no
``relpose`` and a ``torquescale`` of 1. Any other equality stays MuJoCo's, acting on
B_first or B_last as real bodies (see :func:`derods.io.mjcf_cable.set_ends`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from .mjcf_cable import CableDecl
from .mjcf_xml import where

#: How close a connect's anchor must be to the cable's end point [share of the end edge].
ANCHOR_TOL = 1e-2


def to_holds(root: ET.Element, decls: list[CableDecl]) -> list[str]:
    """Turn the equalities that fasten a cable end to a body into holds of the rods in
    ``decls`` (their ``start``/``end`` and ``*_body`` set), removing them from ``root``.
    Returns one note per equality read this way."""
    ends, sites = {}, {}
    for d in decls:
        if d.initial is not None:
            ends[f"{d.prefix}B_first"] = (d, "start")
            ends[f"{d.prefix}B_last"] = (d, "end")
            sites[f"{d.prefix}S_first"] = (d, "start")
            sites[f"{d.prefix}S_last"] = (d, "end")
    site_body = _site_bodies(root)
    notes = []
    for group in root.findall("equality"):
        for eq in list(group):
            hold = _site_hold(eq, sites, site_body) if eq.get("site1") else _hold(eq, ends)
            if hold is None:
                continue
            d, key, kind, other = hold
            setattr(d, key, kind)
            setattr(d, f"{key}_body", other)
            group.remove(eq)
            notes.append(f"{where(eq)}: derods holds rod {d.name!r} by its {key} ({kind}) on "
                         f"{other or 'the world'} instead of this equality (rigidly)")
    return notes


def _site_bodies(root: ET.Element) -> dict[str, str | None]:
    """Each named site's body ("world" for the world body; None for an unnamed body)."""
    out = {}

    def walk(elem: ET.Element, body: str | None):
        for child in elem:
            if child.tag == "site" and child.get("name"):
                out[child.get("name")] = body
            elif child.tag == "body":
                walk(child, child.get("name"))
            elif child.tag == "frame":
                walk(child, body)

    for world in root.findall("worldbody"):
        walk(world, "world")
    return out


def _site_hold(eq: ET.Element, sites: dict, site_body: dict):
    """A connect (pin) or weld (clamp) of a cable's S_first or S_last to a site of another
    body, which must sit where the cable's end does (the equality would pull them together;
    derods holds the end where it starts)."""
    if eq.tag not in ("connect", "weld") or eq.get("active", "true") != "true":
        return None
    s1, s2 = eq.get("site1"), eq.get("site2")
    if (s1 in sites) == (s2 in sites):
        return None
    mine, theirs = (s1, s2) if s1 in sites else (s2, s1)
    other = site_body.get(theirs, None)
    if other is None or theirs in sites:
        return None
    d, key = sites[mine]
    if getattr(d, key) != "free" or (key == "start" and d.initial == "none"):
        return None
    if eq.tag == "weld" and (eq.get("relpose") is not None or float(eq.get("torquescale", "1")) != 1.0):
        return None
    return d, key, "pin" if eq.tag == "connect" else "clamp", None if other == "world" else other


def _hold(eq: ET.Element, ends: dict):
    """(rod, "start" or "end", "pin" or "clamp", the other body or None for the world) if
    ``eq`` can be read as a hold, else None."""
    if eq.tag not in ("connect", "weld") or eq.get("active", "true") != "true":
        return None
    b1 = eq.get("body1")
    if b1 not in ends or eq.get("site1") or eq.get("site2"):
        return None
    other = eq.get("body2") or "world"
    if other in ends:  # another cable's end: left to MuJoCo
        return None
    other = None if other == "world" else other
    d, key = ends[b1]
    if getattr(d, key) != "free" or (key == "start" and d.initial == "none"):
        return None
    if eq.tag == "weld":
        if eq.get("relpose") is not None or float(eq.get("torquescale", "1")) != 1.0:
            return None
        return d, key, "clamp", other
    edges = np.linalg.norm(np.diff(d.x, axis=0), axis=1)
    target = np.zeros(3) if key == "start" else np.array([edges[-1], 0.0, 0.0])
    try:
        anchor = np.array([float(v) for v in eq.get("anchor", "0 0 0").split()])
    except ValueError:
        return None
    if anchor.shape != (3,):
        return None
    scale = edges[0] if key == "start" else edges[-1]
    if np.linalg.norm(anchor - target) > ANCHOR_TOL * scale:
        return None
    return d, key, "pin", other
