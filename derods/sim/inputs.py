"""What a World is given, checked and put in shape before anything is compiled.

The time stepping modes a World knows (:data:`MODES`), the scene read into a
``mujoco.MjSpec`` with the options that override its own (:func:`scene_spec`), and
each rod :meth:`derods.sim.world.World.add_rod` takes (:func:`rod_entry`): checked
against what derods and MuJoCo can simulate, given the twist boundary its ends impose,
and (in the projection mode) a vanishing stretch spring; and the World's own arguments
(:func:`world_options`), a new rod's name (:func:`rod_name`) and a rod given by index or
name (:func:`rod_index`). The checks' vocabulary (what a refusal says) is
:mod:`derods.validation`'s.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace

import mujoco
import numpy as np

from .. import validation
from ..rod import Rod, check_turns
from .clamps import twist_boundary
from .contact_params import ContactParams
from .layout import END_KINDS, RodEntry

#: Time stepping modes of a World ("auto" picks "implicit" or "explicit").
MODES = ("auto", "implicit", "alpha", "explicit", "projection")
#: The lightest vertex [kg] a World accepts (MuJoCo refuses bodies below its mjMINVAL, 1e-15).
MIN_VERTEX_MASS = 1e-12
#: MuJoCo's integrators, by the name World's ``integrator`` takes.
INTEGRATORS = ("euler", "implicit", "implicitfast", "rk4")


def scene_spec(scene, integrator: str | None, dt: float | None, gravity) -> mujoco.MjSpec:
    """The World's ``MjSpec``: ``scene`` itself if a spec, a new one (MuJoCo's implicitfast
    integrator) if None, else the MJCF file it names; then the integrator, dt and gravity
    given (None keeps the scene's)."""
    if isinstance(scene, mujoco.MjSpec):
        spec = scene
    elif scene is None:
        spec = mujoco.MjSpec()
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    else:
        try:
            spec = mujoco.MjSpec.from_file(str(scene))
        except Exception as err:  # MuJoCo raises ValueError with its parser message
            raise validation.InvalidInputError(f"cannot read MJCF scene {str(scene)!r}: {err}") from None
    if integrator is not None:
        spec.option.integrator = getattr(mujoco.mjtIntegrator, "mjINT_" + integrator.upper())
    if dt is not None:
        spec.option.timestep = dt
    if gravity is not None:
        spec.option.gravity = np.asarray(gravity, dtype=float)
    return spec


def rod_entry(spec: mujoco.MjSpec, entries: list[RodEntry], requested_mode: str, rod: Rod, name: str | None,
              start: str, end: str, x, rgba, start_body: str | None, end_body: str | None) -> RodEntry:
    """The rod ``add_rod`` was given, checked, as the world keeps it (see
    :meth:`derods.sim.world.World.add_rod` for the arguments): ``spec`` is the world's
    scene, ``entries`` the rods added before, ``requested_mode`` the World's mode."""
    validation.instance("rod", rod, Rod, "pass derods.Rod(rest_x, material)")
    for key, val in (("start", start), ("end", end)):
        validation.choice(key, val, END_KINDS)
    if rod.closed and (start != "free" or end != "free"):
        raise validation.InvalidInputError(f"start, end: a ring has no ends, got start={start!r}, end={end!r}: "
                                           "leave them 'free'")
    if rod.rest_x.ndim != 2:
        raise validation.InvalidInputError(f"rod: add rods to a World one at a time (rest_x of shape "
                                           f"(n_vertices, 3)), got rest_x of shape {rod.rest_x.shape}")
    name = f"rod{len(entries)}" if name is None else name
    scene_names = {b.name for b in spec.bodies} | {f.name for f in spec.flexes}
    rod_name(name, {e.name: e.rod.n_vertices for e in entries}, scene_names)
    rgba = validation.rgba("rgba", rgba)
    x0 = rod.rest_x if x is None else validation.numeric_array("x", x)
    if x0.shape != rod.rest_x.shape:
        raise validation.InvalidInputError(f"x must have shape {rod.rest_x.shape}, got {x0.shape}")
    if x is not None:
        validation.points("x", x0, rod.closed)
        check_turns("x", x0, rod.closed)
    lightest = float(np.min(rod.vertex_mass))
    if lightest < MIN_VERTEX_MASS:
        raise validation.InvalidInputError(
            f"rod {name!r}: its lightest vertex weighs {lightest:.3g} kg, below what MuJoCo integrates "
            f"({MIN_VERTEX_MASS:g} kg; radius {rod.material.radius:g} m, density {rod.material.density:g} "
            f"kg/m^3, edges {float(np.min(rod.rest_len)):.3g} m): use a larger radius, density or edge length")
    for key, body, kind in (("start", start_body, start), ("end", end_body, end)):
        if body is None:
            continue
        if not isinstance(body, str):
            validation.refuse(f"{key}_body", "the name (str) of a body of the scene", body,
                              "pass the body's name", validation.InvalidTypeError)
        if kind == "free":
            raise validation.InvalidInputError(f"{key}_body={body!r} needs {key}='pin' or 'clamp'")
        if spec.body(body) is None or body == "world":
            names = [b.name for b in spec.bodies if b.name and b.name != "world"]
            raise validation.InvalidInputError(f"{key}_body {body!r} is not a body of the scene; bodies: {names}")
    if not rod.closed:
        rod = rod.with_boundary(twist_boundary(rod, start, end, name))
    if requested_mode == "projection":
        if rod.closed:
            raise validation.InvalidInputError("mode='projection' handles open rods only; use "
                                               "mode='implicit' for rings")
        # Edge lengths are held by projection; a vanishing spring keeps the term's bookkeeping.
        # A rod held by a body with dofs keeps its spring: the coupled solve moves rod and
        # holder together through it (derods.sim.coupled), the projection follows; with
        # the lengths left to the projection alone the holder felt the rod a step late
        # and light or stiff holders diverged at dt 1e-2.
        if not any(_has_dofs(spec, b) for b in (start_body, end_body) if b is not None):
            rod = replace(rod, stretch_stiffness=1e-9 * rod.material.stretch_stiffness)
    entry = RodEntry(name, rod, x0, start, end, start_body, end_body, rgba)
    if entry.fixed.all():
        # (This wording is also the command line's answer.)
        raise validation.InvalidInputError(f"rod '{name}' has every vertex held; give it more edges")
    return entry


def _has_dofs(spec: mujoco.MjSpec, name: str) -> bool:
    """Whether the scene body ``name`` moves by joints of its own or of its ancestors."""
    body = spec.body(name)
    while body is not None and body.name != "world":
        if len(body.joints):
            return True
        body = body.parent
    return False


def world_options(scene, dt, gravity, mode, mass_damping, stiffness_damping, contact, integrator, strain_limit,
                  scene_checks) -> None:
    """World's arguments (the scene is read by :func:`scene_spec`)."""
    if scene is not None and not isinstance(scene, (str, os.PathLike, mujoco.MjSpec)):
        validation.refuse("scene", "None, a path to an MJCF file or a mujoco.MjSpec", scene,
                          "pass a path such as 'scene.xml'", validation.InvalidTypeError)
    validation.choice("mode", mode, MODES)
    if dt is not None:
        validation.real("dt", dt, "s", gt=0, example=2e-3)
    validation.real("mass_damping", mass_damping, "1/s", ge=0, example=0.5)
    validation.real("stiffness_damping", stiffness_damping, "s", ge=0, example=1e-4)
    if gravity is not None:
        validation.vector("gravity", gravity, 3, "m/s^2")
    validation.instance("contact", contact, ContactParams, "pass derods.ContactParams(...)")
    if integrator is not None:
        validation.choice("integrator", integrator.lower() if isinstance(integrator, str) else integrator,
                          INTEGRATORS)
    if strain_limit is not None:
        if not validation.is_real(strain_limit):
            validation.refuse("strain_limit", "a number > 0 (math.inf: off)", strain_limit,
                              "pass a float such as 1e-3", validation.InvalidTypeError)
        if not strain_limit > 0:
            raise validation.InvalidInputError(f"strain_limit must be > 0 (math.inf: off), got {strain_limit!r}")
    validation.boolean("scene_checks", scene_checks)


#: Names MuJoCo and derods' generated bodies can carry: a rod is a body and a flex of its
#: name, its vertices bodies ``f"{name}_{i}"``.
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


def rod_name(name, rods: dict, scene_names: set) -> str:
    """A new rod's name: a plain identifier whose bodies (``name``, ``name_0`` ...) clash
    with no rod's and no scene element's. rods: existing rod names -> vertex counts;
    scene_names: the names of the scene's bodies and flexes."""
    if not isinstance(name, str):
        validation.refuse("name", "a string", name, "pass e.g. 'rope'", validation.InvalidTypeError)
    if not _NAME.match(name):
        validation.refuse("name", "a name of letters, digits, '_', '.' or '-' starting with a letter or '_'", name,
                          "pass e.g. 'rope'")
    if name in rods:
        raise validation.InvalidInputError(f"name: a rod named {name!r} exists already; pass another name")
    m = re.match(r"^(.*)_(\d+)$", name)
    if m and m.group(1) in rods and int(m.group(2)) < rods[m.group(1)]:
        raise validation.InvalidInputError(f"name {name!r} is the name of vertex {m.group(2)} of rod {m.group(1)!r} "
                                           "(its bodies are named rod_vertex); pass another name, such as "
                                           f"{m.group(1) + '-' + m.group(2)!r}")
    for other in rods:
        o = re.match(rf"^{re.escape(name)}_(\d+)$", other)
        if o:
            raise validation.InvalidInputError(f"name {name!r} would name a vertex of this rod {other!r}, a rod of "
                                               "the world (vertex bodies are named rod_vertex); pass another name")
    if name in scene_names:
        raise validation.InvalidInputError(f"name {name!r} is taken by a body or flex of the scene; pass another "
                                           "name")
    return name


def rod_index(rod, names: list):
    """A rod given as an index (int) or a name (str)."""
    if isinstance(rod, str):
        if rod not in names:
            raise validation.InvalidInputError(f"rod {rod!r} is not a rod of the world; rods: {names}")
        return names.index(rod)
    if not validation.is_real(rod) or int(rod) != rod:
        validation.refuse("rod", "a rod index (int) or name (str)", rod, f"rods: {names}", validation.InvalidTypeError)
    i = int(rod)
    if not -len(names) <= i < len(names):
        raise validation.InvalidIndexError(f"rod index {i} out of range; the world has {len(names)} rods: {names}")
    return i % len(names)
