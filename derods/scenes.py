"""The MJCF scenes that ship with derods: floor, box, table_edge, stairs, pegs, halfpipe, rail, head
(the hair scene) and gripper (examples/grasp.py).

They live in ``mjcf/`` at the top of the repository and are installed inside the
package as ``derods.mjcf``, read here with :mod:`importlib.resources`, so an
installed wheel finds them wherever it is. An editable install (``pip install
-e``) puts the repository itself on the path, where they are read from ``mjcf/``
next to the package.
"""

from __future__ import annotations

import pathlib
from importlib import resources


def _folder():
    try:
        return resources.files("derods.mjcf")
    except ModuleNotFoundError:  # a source checkout: mjcf/ beside the package
        return pathlib.Path(__file__).resolve().parents[1] / "mjcf"


def names() -> list[str]:
    """Names of the scenes that ship with derods."""
    return sorted(p.name[:-4] for p in _folder().iterdir() if p.name.endswith(".xml"))


def path(scene: str | pathlib.Path) -> pathlib.Path:
    """The MJCF file of a scene given by name ("box") or by path ("my_scene.xml").

    Raises ValueError naming the choices for an unknown name or a missing file."""
    text = str(scene)
    named = _folder() / f"{text}.xml"
    if "/" not in text and "\\" not in text and named.is_file():
        return pathlib.Path(str(named))
    p = pathlib.Path(text)
    if p.suffix.lower() == ".xml" or p.exists():
        if not p.is_file():
            raise ValueError(f"scene file {text!r} does not exist")
        return p
    raise ValueError(f"unknown scene {text!r}; choose one of {', '.join(names())} or give an MJCF path")
