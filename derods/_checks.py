"""Input validation that names the parameter, its value and what to do."""

from __future__ import annotations

import numpy as np


def positive(name: str, value, unit: str = "") -> np.ndarray | float:
    """Return ``value`` if every entry is finite and > 0, else raise ValueError."""
    arr = np.asarray(value, dtype=float)
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        bad = arr if arr.ndim == 0 else arr[~(np.isfinite(arr) & (arr > 0))][:3]
        unit_txt = f" [{unit}]" if unit else ""
        got = repr(float(bad)) if bad.ndim == 0 else f"entries {bad.tolist()}"
        raise ValueError(f"{name} must be finite and > 0{unit_txt}, got {got}")
    return float(arr) if arr.ndim == 0 else arr


def non_negative(name: str, value, unit: str = "") -> np.ndarray | float:
    """Return ``value`` if every entry is finite and >= 0, else raise ValueError."""
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        unit_txt = f" [{unit}]" if unit else ""
        raise ValueError(f"{name} must be finite and >= 0{unit_txt}, got {value!r}")
    return float(arr) if arr.ndim == 0 else arr


def points(name: str, x, closed: bool = False) -> np.ndarray:
    """Check a vertex array of shape (..., n_vertices, 3): finite, enough edges, no zero edge.

    An open rod needs at least 2 edges (3 vertices); a closed rod at least 3 edges
    (3 vertices). Zero-length edges would make tangents undefined.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim < 2 or x.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., n_vertices, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(x))[0])
        raise ValueError(f"{name} has a NaN or infinite coordinate at index {idx}")
    nv = x.shape[-2]
    n_edges = nv if closed else nv - 1
    need = 3 if closed else 2
    if n_edges < need:
        kind = "closed" if closed else "open"
        raise ValueError(
            f"{name}: a {kind} rod needs at least {need} edges, got {n_edges} "
            f"({nv} vertices); add vertices"
        )
    e = (np.roll(x, -1, axis=-2) - x) if closed else np.diff(x, axis=-2)
    le = np.linalg.norm(e, axis=-1)
    scale = max(float(np.max(le)), 1e-300)
    if np.any(le <= 1e-12 * scale):
        j = int(np.argwhere(le <= 1e-12 * scale)[0][-1])
        raise ValueError(
            f"{name}: edge {j} has zero length (vertices {j} and {(j + 1) % nv} coincide); "
            "remove duplicate vertices"
        )
    return x
