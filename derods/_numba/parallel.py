"""Rods in parallel: the per-rod kernels of a step, run on numba's threads for a world of
many rods.

In three stages of a step every rod's work is its own: its terms and band
(:func:`derods._numba.step.rods_step`), its diagonal block of the implicit matrix, which
is block diagonal over rods, with its factor and solves
(:func:`derods._numba.implicit.unconstrained_step`), and its strain limit
(:func:`derods._numba.projection.limit_strain`). Each of these kernels loops over the
chunks of a :class:`Split`, runs of whole rods, and each chunk over its rods in order,
doing for them exactly what one chunk of all rods does: so whatever the chunks, the
results are the same to the bit (tests/test_parallel.py holds a world of many rods to
that). Each kernel is compiled twice from its one Python function
(:func:`compiled_twice`): serially, where ``prange`` is ``range``, and with numba's
``parallel=True``, where the chunks run on numba's threads.

A parallel launch costs microseconds a kernel, as much as a small world's whole rod
stage: :func:`plan` gives a world the parallel kernels only when its chunks are at least
:data:`MIN_CHUNK_VERTICES` vertices each, one chunk a thread. Cap the threads with
``numba.set_num_threads(k)`` (or ``NUMBA_NUM_THREADS=k``) before a world compiles: with
one thread it keeps the serial kernels.

numba's threading layer is TBB, OpenMP or its own workqueue, the first it finds (pip's
numba always has the workqueue; OpenMP needs the system's libgomp). The workqueue must
not be entered by two threads at once: the parallel kernels are called under
:data:`LOCK`. GNU OpenMP cannot run in a child forked after it started: such a child
keeps to the serial kernels.
"""

from __future__ import annotations

import os
import threading
import types
from typing import NamedTuple

import numba as nb
import numpy as np

#: Fewest vertices a chunk of rods takes for a world to step in parallel (see
#: docs/performance.md for how it was measured).
MIN_CHUNK_VERTICES = 256
#: Held around every call of a parallel kernel: numba's workqueue layer aborts the
#: process when two threads launch parallel work at once (two worlds stepped in threads).
LOCK = threading.Lock()

_after_gnu_fork = False  # set in a child forked from a process running numba's OpenMP threads


class Split(NamedTuple):
    """Chunks of whole rods, each a run of consecutive rods: chunk c holds rods
    rods[c] .. rods[c + 1] - 1, their dofs dofs[c] .. dofs[c + 1] - 1 (in the solve order)
    and their twist terms twists[c] .. twists[c + 1] - 1; each shape (n_chunks + 1,), int64."""

    rods: np.ndarray
    dofs: np.ndarray
    twists: np.ndarray

    @property
    def parallel(self) -> bool:
        """Whether the step takes the parallel kernels (more than one chunk)."""
        return len(self.rods) > 2


def threads() -> int:
    """The threads numba runs parallel kernels on: 1 in a child forked from a process that
    started numba's GNU OpenMP threads (they would abort it)."""
    return 1 if _after_gnu_fork else nb.get_num_threads()


def plan(v_off: np.ndarray, dof_off: np.ndarray, tw_rod: np.ndarray) -> Split:
    """A world's chunks of rods (:func:`split`): one a thread (:func:`threads`) as long as
    each holds at least :data:`MIN_CHUNK_VERTICES` vertices; one chunk (the serial
    kernels) when fewer than two would. Arguments as :func:`split`'s."""
    n_rods, n_vertices = len(v_off) - 1, int(v_off[-1])
    return split(v_off, dof_off, tw_rod, min(threads(), n_rods, n_vertices // MIN_CHUNK_VERTICES))


def split(v_off: np.ndarray, dof_off: np.ndarray, tw_rod: np.ndarray, n_chunks: int) -> Split:
    """The rods in ``n_chunks`` runs (fewer if there are fewer rods; at least one), cut
    between the rods nearest to equal shares of the vertices.

    v_off, dof_off (n_rods + 1,): each rod's first vertex and first dof (of the solve
    order); tw_rod (T,): the rod of each twist term of the implicit system, ascending.
    """
    n_rods, n_vertices = len(v_off) - 1, int(v_off[-1])
    n = min(n_chunks, n_rods)
    inner = np.searchsorted(v_off, np.arange(1, n) * (n_vertices / n)) if n > 1 else np.zeros(0, dtype=np.int64)
    cuts = np.concatenate([[0], np.unique(np.clip(inner, 1, n_rods - 1)), [n_rods]]).astype(np.int64)
    return Split(cuts, np.asarray(dof_off, dtype=np.int64)[cuts],
                 np.searchsorted(np.asarray(tw_rod, dtype=np.int64), cuts).astype(np.int64))


def compiled_twice(fn):
    """``fn`` njit-compiled serially and in parallel: two dispatchers from one body. The
    parallel one's function is a copy named ``<name>_parallel``: numba's disk cache keys
    its files by a function's name and its bytecode, not by ``parallel``, and would
    otherwise hand one variant's machine code to the other."""
    twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_parallel", fn.__defaults__,
                              fn.__closure__)
    twin.__qualname__ = fn.__qualname__ + "_parallel"
    twin.__doc__ = fn.__doc__
    return nb.njit(cache=True)(fn), nb.njit(cache=True, parallel=True)(twin)


def _after_fork_in_child() -> None:
    global _after_gnu_fork
    try:
        layer = nb.threading_layer()
    except ValueError:  # no parallel kernel has run: the child may start any layer
        return
    if layer == "omp":
        _after_gnu_fork = True


os.register_at_fork(after_in_child=_after_fork_in_child)
