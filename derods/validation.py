"""What derods refuses at its public boundary, and how it says so.

Every public constructor and :class:`~derods.World` method checks its inputs here, so
that a value derods cannot simulate stops at once, with a message that names the
parameter, the value and what to pass instead:
``young must be a finite number > 0 [Pa], got '1e7' (str): pass a float such as 1e7``.

A refusal is an :class:`InvalidInputError` (a ``ValueError``); a value of the wrong
kind (a string for a number, a number where a :class:`~derods.Material` belongs) is an
:class:`InvalidTypeError`, which is also a ``TypeError``. Checks of a compiled scene
(a step too long for the fall, a rod starting inside an obstacle) are
:mod:`derods.sim.scene_checks`; what a lost solution looks like is
:mod:`derods.sim.divergence`.
"""

from __future__ import annotations

import math
import numbers
import re

import numpy as np


class InvalidInputError(ValueError):
    """An input derods cannot simulate; the message names the parameter, the value and a fix."""


class InvalidTypeError(InvalidInputError, TypeError):
    """An input of the wrong kind (a string for a number, a number for a Material)."""


class InvalidIndexError(InvalidInputError, IndexError):
    """An index out of range (a rod, a vertex); also an ``IndexError``."""


class SceneWarning(UserWarning):
    """A scene that may not do what it looks like (a step too long for the fall, a rod
    starting inside an obstacle or stretched between its holds). Silence it with
    ``World(..., scene_checks=False)`` or ``warnings.simplefilter("ignore", derods.SceneWarning)``."""


def shown(value) -> str:
    """A value as a message shows it: numbers plainly, anything else with its type."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.ndarray)):
        text = repr(value)
        if len(text) > 60:
            text = text[:57] + "..."
        return f"{text} ({type(value).__name__})"
    if isinstance(value, np.ndarray):
        return f"array of shape {value.shape}" if value.size > 6 else repr(value.tolist())
    return repr(value)


def refuse(name: str, need: str, value, fix: str = "", kind=InvalidInputError):
    """Raise ``kind`` saying ``name must be <need>, got <value>: <fix>``."""
    raise kind(f"{name} must be {need}, got {shown(value)}" + (f": {fix}" if fix else ""))


def is_real(value) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "iuf"
    return isinstance(value, numbers.Real)


def _bounds(gt, ge, lt, le) -> str:
    parts = [f"> {gt:g}" if gt is not None else None, f">= {ge:g}" if ge is not None else None,
             f"< {lt:g}" if lt is not None else None, f"<= {le:g}" if le is not None else None]
    return " and ".join(p for p in parts if p)


def real(name: str, value, unit: str = "", *, gt=None, ge=None, lt=None, le=None, example=None) -> float:
    """``value`` as a float if it is a finite real number within the bounds, else refuse it.

    unit: shown in brackets. example: a value to suggest (default: none).
    """
    bounds = _bounds(gt, ge, lt, le)
    unit_txt = f" [{unit}]" if unit else ""
    if not is_real(value):
        hint = f"pass a float such as {example!r}" if example is not None else "pass a float"
        refuse(name, "a finite number" + (f" {bounds}" if bounds else "") + unit_txt, value, hint, InvalidTypeError)
    v = float(value)
    if (not math.isfinite(v) or (gt is not None and not v > gt) or (ge is not None and not v >= ge)
            or (lt is not None and not v < lt) or (le is not None and not v <= le)):
        # The bounds are what to do; this wording is also the command line's answer.
        raise InvalidInputError(f"{name} must be finite" + (f" and {bounds}" if bounds else "") + unit_txt
                                + f", got {value!r}")
    return v


def positive(name: str, value, unit: str = "", example=None):
    """A finite number > 0 (or, for an array, every entry); returned as float or array."""
    if isinstance(value, (np.ndarray, list, tuple)) and np.ndim(value) > 0:
        arr = numeric_array(name, value)
        if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            bad = arr[~(np.isfinite(arr) & (arr > 0))][:3]
            raise InvalidInputError(f"{name} must be finite and > 0" + (f" [{unit}]" if unit else "")
                                    + f", got entries {bad.tolist()}")
        return arr
    return real(name, value, unit, gt=0, example=example)


def non_negative(name: str, value, unit: str = "", example=None) -> float:
    """A finite number >= 0, as a float."""
    return real(name, value, unit, ge=0, example=example)


def integer(name: str, value, *, ge: int | None = None, le: int | None = None) -> int:
    """``value`` as an int if it is a whole number within the bounds (2.0 is 2), else refuse it."""
    bounds = _bounds(None, ge, None, le)
    need = "an integer" + (f" {bounds}" if bounds else "")
    if not is_real(value):
        refuse(name, need, value, "pass an int", InvalidTypeError)
    if not math.isfinite(float(value)) or int(value) != value:
        refuse(name, need, value, "pass a whole number")
    v = int(value)
    if (ge is not None and v < ge) or (le is not None and v > le):
        refuse(name, need, value)
    return v


def boolean(name: str, value) -> bool:
    """``value`` if it is True or False; a string such as "False" is refused (it would read as True)."""
    if not isinstance(value, (bool, np.bool_)):
        refuse(name, "True or False", value, "pass a bool", InvalidTypeError)
    return bool(value)


def choice(name: str, value, options) -> str:
    """``value`` if it is one of ``options``, else refuse it, listing them."""
    if not isinstance(value, str):
        refuse(name, f"one of {tuple(options)}", value, "pass one of these strings", InvalidTypeError)
    if value not in options:
        refuse(name, f"one of {tuple(options)}", value)
    return value


def instance(name: str, value, cls, fix: str):
    """``value`` if it is an instance of ``cls``, else refuse it (a type error)."""
    if not isinstance(value, cls):
        refuse(name, f"a {cls.__name__}", value, fix, InvalidTypeError)
    return value


def numeric_array(name: str, value) -> np.ndarray:
    """``value`` as a float array, refusing strings, None and ragged or non-numeric lists."""
    if isinstance(value, (str, bytes)) or value is None:
        refuse(name, "an array of numbers", value, "pass a numpy array or a list of floats", InvalidTypeError)
    try:
        arr = np.asarray(value)
    except ValueError:  # a ragged list
        refuse(name, "an array of numbers", value, "give every row the same length", InvalidTypeError)
    if arr.dtype.kind not in "iuf":
        refuse(name, "an array of numbers", value, "pass a numpy array or a list of floats", InvalidTypeError)
    return arr.astype(float, copy=False)


def vector(name: str, value, n: int = 3, unit: str = "", *, nonzero: bool = False) -> np.ndarray:
    """``value`` as a finite float array of shape (n,)."""
    need = f"{n} finite numbers" + (f" [{unit}]" if unit else "") + (", not all zero" if nonzero else "")
    if is_real(value):
        refuse(name, need, value, f"pass a sequence of {n} floats", InvalidTypeError)
    arr = numeric_array(name, value)
    if arr.shape != (n,):
        refuse(name, need, value, f"pass {n} floats")
    if not np.all(np.isfinite(arr)) or (nonzero and not np.any(arr)):
        refuse(name, need, arr)
    return arr


def finite_array(name: str, value, shape: tuple, unit: str = "") -> np.ndarray:
    """``value`` as a float array of ``shape``, every entry finite (naming the first that is not)."""
    arr = numeric_array(name, value)
    if arr.shape != shape:
        raise InvalidInputError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise InvalidInputError(f"{name} has a NaN or infinite entry at index {idx}"
                                + (f" [{unit}]" if unit else "") + ": pass finite values")
    return arr


def points(name: str, x, closed: bool = False) -> np.ndarray:
    """Check a vertex array of shape (..., n_vertices, 3): finite, enough edges, no zero edge.

    An open rod needs at least 2 edges (3 vertices); a closed rod at least 3 edges
    (3 vertices). Zero-length edges would make tangents undefined.
    """
    x = numeric_array(name, x)
    if x.ndim < 2 or x.shape[-1] != 3:
        raise InvalidInputError(f"{name} must have shape (..., n_vertices, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(x))[0])
        raise InvalidInputError(f"{name} has a NaN or infinite coordinate at index {idx}")
    nv = x.shape[-2]
    n_edges = nv if closed else nv - 1
    need = 3 if closed else 2
    if n_edges < need:
        kind = "closed" if closed else "open"
        raise InvalidInputError(
            f"{name}: a {kind} rod needs at least {need} edges, got {n_edges} "
            f"({nv} vertices); add vertices"
        )
    e = (np.roll(x, -1, axis=-2) - x) if closed else np.diff(x, axis=-2)
    le = np.linalg.norm(e, axis=-1)
    scale = max(float(np.max(le)), 1e-300)
    if np.any(le <= 1e-12 * scale):
        j = int(np.argwhere(le <= 1e-12 * scale)[0][-1])
        raise InvalidInputError(
            f"{name}: edge {j} has zero length (vertices {j} and {(j + 1) % nv} coincide); "
            "remove duplicate vertices"
        )
    return x


def rgba(name: str, value) -> tuple:
    """Four numbers in [0, 1] (red, green, blue, alpha), as a tuple of floats."""
    need, fix = "4 numbers in [0, 1] (red, green, blue, alpha)", "pass e.g. (0.9, 0.3, 0.15, 1.0)"
    if is_real(value):
        refuse(name, need, value, fix, InvalidTypeError)
    arr = numeric_array(name, value)
    if arr.shape != (4,) or not np.all((arr >= 0) & (arr <= 1)):
        refuse(name, need, value, fix)
    return tuple(float(c) for c in arr)


# -- the public classes' own checks ---------------------------------------------------------

#: Contact dimensionalities MuJoCo accepts: frictionless, sliding, + torsional, + rolling.
CONDIMS = (1, 3, 4, 6)


def material(m) -> None:
    """A :class:`~derods.Material`'s constants, each named with its unit."""
    from .material import MAX_MODULUS

    real("young", m.young, "Pa", gt=0, example=1e7)
    real("density", m.density, "kg/m^3", gt=0, example=1000.0)
    real("radius", m.radius, "m", gt=0, example=0.01)
    if m.radius2 is not None:
        real("radius2", m.radius2, "m", gt=0, example=0.005)
    if m.shear is not None:
        real("shear", m.shear, "Pa", gt=0, example=3e6)
    else:
        if not is_real(m.poisson):
            refuse("poisson", "a number in (-1, 0.5]", m.poisson, "pass a float such as 0.5", InvalidTypeError)
        if not -1.0 < m.poisson <= 0.5:
            raise InvalidInputError(f"poisson must be in (-1, 0.5], got {m.poisson!r}")
    for name in ("young", "shear"):
        value = getattr(m, name)
        if value is not None and value > MAX_MODULUS:
            raise InvalidInputError(f"{name} = {value:g} Pa is stiffer than any material (diamond: 1.2e12 Pa); "
                                    f"use a modulus <= {MAX_MODULUS:g} Pa")


def twist_boundary(b) -> None:
    """A :class:`~derods.TwistBoundary`'s kind and angles."""
    choice("TwistBoundary.kind", b.kind, ("free", "clamped", "ring"))
    if b.kind == "clamped" and (b.theta_first is None or b.theta_last is None):
        raise InvalidInputError("a clamped TwistBoundary needs theta_first and theta_last [rad], got "
                                f"theta_first={b.theta_first!r}, theta_last={b.theta_last!r}")
    for key in ("theta_first", "theta_last"):
        if getattr(b, key) is not None:
            real(f"TwistBoundary.{key}", getattr(b, key), "rad", example=0.0)
    real("TwistBoundary.total_twist", b.total_twist, "rad", example=0.0)


def rod_fields(rod) -> np.ndarray:
    """A :class:`~derods.Rod`'s parameters but its shape's turns; returns rest_x as floats."""
    from .geometry import BENDING_MEASURES
    from .material import Material
    from .twist import TwistBoundary

    instance("material", rod.material, Material, "pass derods.Material(young=...)")
    closed = boolean("closed", rod.closed)
    boolean("natural_curvature", rod.natural_curvature)
    instance("boundary", rod.boundary, TwistBoundary, "pass derods.TwistBoundary(...)")
    x = points("rest_x", rod.rest_x, closed)
    if closed and rod.boundary.kind != "ring":
        raise InvalidInputError("a closed rod needs boundary=TwistBoundary('ring', total_twist=...), got "
                                f"boundary kind {rod.boundary.kind!r}")
    if not closed and rod.boundary.kind == "ring":
        raise InvalidInputError("TwistBoundary('ring') is for closed rods; pass closed=True")
    if rod.stretch_stiffness is not None:
        real("stretch_stiffness", rod.stretch_stiffness, "N", gt=0, example=1e3)
    if is_real(rod.rest_twist):
        real("rest_twist", rod.rest_twist, "rad", example=0.0)
    else:
        tw = numeric_array("rest_twist", rod.rest_twist)
        n_joints = x.shape[-2] if closed else x.shape[-2] - 2
        try:
            np.broadcast_to(tw, x.shape[:-2] + (n_joints,))
        except ValueError:
            raise InvalidInputError(f"rest_twist must be a number or one per joint ({n_joints}), got shape "
                                    f"{tw.shape}") from None
        if not np.all(np.isfinite(tw)):
            raise InvalidInputError(f"rest_twist must be finite [rad], got a NaN or infinite entry at joint "
                                    f"{int(np.flatnonzero(~np.isfinite(tw.ravel()))[0])}: pass finite angles")
    if rod.u0 is not None:
        vector("u0", rod.u0, 3, nonzero=True)
    if not isinstance(rod.bending, str) or rod.bending not in BENDING_MEASURES:
        refuse("bending", "'tan' (Bergou's curvature binormal, the default) or 'angle' (the turning angle)",
               rod.bending, "pass bending='angle' to bend as MuJoCo's cable does, or leave it out",
               InvalidInputError if isinstance(rod.bending, str) else InvalidTypeError)
    return x


def contact_params(c) -> None:
    """A :class:`~derods.ContactParams`: each value within what MuJoCo simulates as meant."""
    real("friction", c.friction, ge=0, example=1.0)
    ref = vector("solref", c.solref, 2) if is_real(c.solref) or np.size(c.solref) == 2 else None
    if ref is None:
        refuse("solref", "2 finite numbers (timeconst [s], dampratio)", c.solref, "pass e.g. (0.005, 1.0)")
    if not ((ref[0] > 0 and ref[1] > 0) or (ref[0] < 0 and ref[1] <= 0)):
        refuse("solref", "(timeconst > 0 [s], dampratio > 0), or (-stiffness < 0, -damping <= 0)",
               tuple(ref.tolist()), "pass e.g. (0.005, 1.0)")
    imp = numeric_array("solimp", c.solimp)
    need = ("3 or 5 finite numbers (dmin, dmax, width [m], midpoint, power) with 0 < dmin <= dmax < 1, "
            "width >= 0, 0 < midpoint < 1, power >= 1")
    if imp.shape not in ((3,), (5,)) or not np.all(np.isfinite(imp)):
        refuse("solimp", need, c.solimp, "pass e.g. (0.9, 0.95, 0.001, 0.5, 2.0)")
    ok = 0 < imp[0] <= imp[1] < 1 and imp[2] >= 0
    if len(imp) == 5:
        ok = ok and 0 < imp[3] < 1 and imp[4] >= 1
    if not ok:
        refuse("solimp", need, tuple(imp.tolist()), "pass e.g. (0.9, 0.95, 0.001, 0.5, 2.0)")
    k = integer("condim", c.condim)
    if k not in CONDIMS:
        refuse("condim", f"one of {CONDIMS} (1 frictionless, 3 sliding, 4 torsional, 6 rolling)", c.condim)
    for key in ("self_collision", "rod_rod", "holder_contact", "static_friction"):
        boolean(key, getattr(c, key))
    if c.speculative is not None:
        boolean("speculative", c.speculative)
    real("margin", c.margin, "m", ge=0, example=0.0)
    integer("priority", c.priority)


def rod_state(rod, state, name: str = "state") -> None:
    """A :class:`~derods.RodState` of ``rod``'s sizes (x (..., n_vertices, 3), u and t
    (..., n_edges, 3), theta (..., n_edges))."""
    from .rod_state import RodState

    instance(name, state, RodState, "pass rod.rest_state() or a state from rod.advance()")
    nv, ne = rod.n_vertices, rod.n_edges
    for key, tail in (("x", (nv, 3)), ("u", (ne, 3)), ("t", (ne, 3)), ("theta", (ne,))):
        shape = np.shape(getattr(state, key))
        if len(shape) < len(tail) or shape[len(shape) - len(tail):] != tail:
            raise InvalidInputError(f"{name}.{key} must have shape (..., {', '.join(map(str, tail))}) for this rod "
                                    f"({nv} vertices), got {shape}")


def rod_positions(rod, x, name: str = "x") -> None:
    """Finite vertex positions [m] of ``rod``'s size, shape (..., n_vertices, 3)."""
    arr = numeric_array(name, x)
    if arr.ndim < 2 or arr.shape[-2:] != (rod.n_vertices, 3):
        raise InvalidInputError(f"{name} must have shape (..., {rod.n_vertices}, 3) for this rod, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise InvalidInputError(f"{name} has a NaN or infinite coordinate at index {idx}: pass finite positions")
