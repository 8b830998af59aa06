"""MJCF as a tree of elements: reading it with line numbers, inlining includes, resolving
default classes, and reading attributes with one-line refusals.

The refusals are :class:`derods.validation.InvalidInputError` naming the element (its
tag, name or prefix, and line in the file), the attribute, the value and the fix.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import numpy as np

from .. import validation

#: Each element's (file, line), filled by :func:`parse`.
_LINES: dict[int, tuple[str, int]] = {}


def parse(text: str, source: str) -> ET.Element:
    """The root element of MJCF ``text`` (``source`` names it in messages), each element's
    line noted for messages."""
    import xml.parsers.expat

    name = os.path.basename(source)
    builder = ET.TreeBuilder()
    parser = xml.parsers.expat.ParserCreate()

    def start(tag, attrs):
        elem = builder.start(tag, attrs)
        _LINES[id(elem)] = (name, parser.CurrentLineNumber)

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    try:
        parser.Parse(text, True)
        return builder.close()
    except xml.parsers.expat.ExpatError as err:
        raise validation.InvalidInputError(f"cannot read MJCF scene {source!r}: {err}") from None


def forget() -> None:
    """Drop the noted lines (of the files read before: a new load starts afresh)."""
    _LINES.clear()


def read(path: str) -> ET.Element:
    """The root of the MJCF file ``path``, its ``<include file=...>`` elements replaced by the
    included files' elements (as MuJoCo does, relative to the including file's folder)."""
    try:
        with open(path, encoding="utf-8") as f:
            root = parse(f.read(), path)
    except OSError as err:
        raise validation.InvalidInputError(f"cannot read MJCF scene {path!r}: {err.strerror}") from None
    _inline_includes(root, os.path.dirname(os.path.abspath(path)))
    return root


def _inline_includes(elem: ET.Element, folder: str) -> None:
    for i, child in enumerate(list(elem)):
        if child.tag == "include":
            inc = os.path.join(folder, child.get("file", ""))
            sub = read(inc)
            elem.remove(child)
            # An included file's root is <mujoco>: its children take the include's place.
            for k, c in enumerate(list(sub)):
                elem.insert(i + k, c)
            _inline_includes(elem, folder)
            return
        _inline_includes(child, folder)


def where(elem: ET.Element, label: str | None = None) -> str:
    """How messages name an element: ``body 'arm' (cable.xml line 12)``, or with ``label``
    instead of its name: ``composite prefix 'a' (cable.xml line 4)``."""
    src, line = _LINES.get(id(elem), ("", 0))
    name = label if label else (repr(elem.get("name")) if elem.get("name") else "")
    text = elem.tag + (f" {name}" if name else "")
    return f"{text} ({src} line {line})" if line else text


def refuse(elem: ET.Element, message: str, label: str | None = None):
    """Raise the one-line refusal ``<element>: <message>``."""
    raise validation.InvalidInputError(f"{where(elem, label)}: {message}")


def numbers(elem: ET.Element, attr: str, count, default=None, label: str | None = None,
            example: str = "") -> np.ndarray | None:
    """Attribute ``attr`` as floats, shape (k,), k in ``count`` (an int or a tuple of ints);
    ``default`` (None: absent is None) when absent; refuse anything else."""
    text = elem.get(attr)
    if text is None:
        return None if default is None else np.asarray(default, dtype=float)
    counts = (count,) if isinstance(count, int) else tuple(count)
    try:
        vals = np.array([float(t) for t in text.split()])
    except ValueError:
        vals = None
    if vals is None or len(vals) not in counts or not np.all(np.isfinite(vals)):
        need = " or ".join(str(c) for c in counts)
        refuse(elem, f'{attr}="{text}" must be {need} finite number(s)' + (f': write e.g. {attr}="{example}"'
                                                                              if example else ""), label)
    return vals


def number(elem: ET.Element, attr: str, default: float, label: str | None = None, *, ge=None, gt=None,
           unit: str = "", example: str = "") -> float:
    """Attribute ``attr`` as one float within bounds (``default`` when absent)."""
    v = numbers(elem, attr, 1, [default], label, example)[0]
    if (ge is not None and v < ge) or (gt is not None and v <= gt):
        bound = f">= {ge:g}" if ge is not None else f"> {gt:g}"
        refuse(elem, f'{attr}="{elem.get(attr)}" must be {bound}' + (f" [{unit}]" if unit else "")
               + (f': write e.g. {attr}="{example}"' if example else ""), label)
    return float(v)


# -- default classes ----------------------------------------------------------------------

def default_classes(root: ET.Element) -> dict[str, tuple[str | None, ET.Element]]:
    """Every ``<default>`` class of the model by name ("main" for the top one): its parent
    class's name and its element."""
    out: dict[str, tuple[str | None, ET.Element]] = {}

    def walk(d: ET.Element, parent: str | None):
        name = d.get("class", "main")
        out[name] = (parent, d)
        for c in d.findall("default"):
            walk(c, name)

    for d in root.findall("default"):
        walk(d, None)
    return out


def resolved(elem: ET.Element, kind: str, cls: str | None, classes: dict) -> dict[str, str]:
    """The attributes of ``elem`` (a ``kind`` element: geom, joint, site) with those its
    default class gives (``elem``'s own ``class``, else ``cls``, else "main"), own ones first."""
    chain = []
    name = elem.get("class", cls) or "main"
    while name is not None and name in classes:
        parent, d = classes[name]
        chain.append(d)
        name = parent
    out: dict[str, str] = {}
    for d in reversed(chain):
        spec = d.find(kind)
        if spec is not None:
            out.update(spec.attrib)
    out.update({k: v for k, v in elem.attrib.items() if k != "class"})
    return out


def with_defaults(elem: ET.Element, kind: str, cls: str | None, classes: dict) -> ET.Element:
    """A copy of ``elem`` carrying its default class's attributes too (:func:`resolved`),
    named in messages where ``elem`` is."""
    out = ET.Element(elem.tag, resolved(elem, kind, cls, classes))
    if id(elem) in _LINES:
        _LINES[id(out)] = _LINES[id(elem)]
    return out


def childclass(parents: list[ET.Element]) -> str | None:
    """The nearest ``childclass`` among the enclosing bodies (innermost last in ``parents``)."""
    for p in reversed(parents):
        if p.get("childclass"):
            return p.get("childclass")
    return None
