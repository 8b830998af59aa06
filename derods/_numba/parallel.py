"""Rods in parallel: the per-rod kernels of a step, run on threads for a world of many rods.

In three stages of a step every rod's work is its own: its terms and band
(:func:`derods._numba.step.rods_step`), its diagonal block of the implicit matrix, which
is block diagonal over rods, with its factor and solves
(:func:`derods._numba.implicit.unconstrained_step`), and its strain limit
(:func:`derods._numba.projection.limit_strain`). Each of these kernels takes a
:class:`Split` of the rods into chunks, runs of whole rods, and does for each chunk's rods
in order exactly what it does for all rods at once: so whatever the chunks, the results
are the same to the bit (tests/test_parallel.py holds a world of many rods to that). The
kernels release the GIL (``nogil``), and a :class:`Runner` calls one of them once per
chunk, the first chunk in the calling thread and the others on worker threads.

Why Python threads rather than numba's ``parallel=True``: measured on the 2-core VM, the
same kernels with ``prange`` over the chunks took 11 s more to compile from scratch (numba
compiles each parallel loop's body again, with every kernel it calls), and on a machine
whose other core was busy a parallel region waited up to a scheduler tick (4-8 ms) for
its spinning threads, where a thread handed its chunk through a queue costs ~20 us.

A hand-off costs that much a kernel call, several times a small world's rod stage:
:func:`plan` gives a world threads only when each chunk holds at least
:data:`MIN_CHUNK_VERTICES` vertices, one chunk a thread. The threads are numba's count,
``numba.config.NUMBA_NUM_THREADS`` (the cores this process may use; set
``NUMBA_NUM_THREADS=k`` in the environment to cap it, 1 for none), read when a world
compiles.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numba as nb
import numpy as np

from .calls import Bound

#: Fewest vertices a chunk of rods takes for a world to step on threads (see
#: docs/performance.md for how it was measured).
MIN_CHUNK_VERTICES = 256

_pool: ThreadPoolExecutor | None = None  # the worker threads, made at first use


class Split(NamedTuple):
    """Chunks of whole rods, each a run of consecutive rods: chunk c holds rods
    rods[c] .. rods[c + 1] - 1, their dofs dofs[c] .. dofs[c + 1] - 1 (in the solve order)
    and their twist terms twists[c] .. twists[c + 1] - 1; each shape (n_chunks + 1,), int64."""

    rods: np.ndarray
    dofs: np.ndarray
    twists: np.ndarray

    @property
    def parallel(self) -> bool:
        """Whether the chunks run on threads (more than one)."""
        return len(self.rods) > 2

    def parts(self) -> list["Split"]:
        """One single-chunk Split per chunk."""
        return [Split(self.rods[c:c + 2], self.dofs[c:c + 2], self.twists[c:c + 2]) for c in range(len(self.rods) - 1)]


def threads() -> int:
    """The threads a world's rods may run on: numba's count (``NUMBA_NUM_THREADS``)."""
    return max(1, int(nb.config.NUMBA_NUM_THREADS))


def plan(v_off: np.ndarray, dof_off: np.ndarray, tw_rod: np.ndarray) -> Split:
    """A world's chunks of rods (:func:`split`): one a thread (:func:`threads`) as long as
    each holds at least :data:`MIN_CHUNK_VERTICES` vertices; one chunk (no threads) when
    fewer than two would. Arguments as :func:`split`'s."""
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


class Runner:
    """A per-rod kernel (a numba dispatcher whose last argument is the split: the Split
    itself if ``bundle``, else its ``rods``) called once per chunk of ``split``: the first
    chunk in the calling thread, the others on worker threads. A call returns the chunks'
    results in order; if a chunk raised, it waits for the others (they write the same
    arrays) and raises the first chunk's exception."""

    def __init__(self, kernel, split: Split, bundle: bool = False):
        self.parts = [p if bundle else p.rods for p in split.parts()] if split.parallel else \
            [split if bundle else split.rods]
        # A Bound each: its bookkeeping is not shared between threads.
        self.calls = [Bound(kernel) for _ in self.parts]

    def __call__(self, *args) -> list:
        if len(self.parts) == 1:
            return [self.calls[0](*args, self.parts[0])]
        pool = _workers()
        futures = [pool.submit(call, *args, part) for call, part in zip(self.calls[1:], self.parts[1:])]
        results, errors = [], []
        for run in [lambda: self.calls[0](*args, self.parts[0])] + [f.result for f in futures]:
            try:
                results.append(run())
            except Exception as err:  # noqa: BLE001 - re-raised below, once every chunk is done
                results.append(None)
                errors.append(err)
        if errors:
            raise errors[0]
        return results


def _workers() -> ThreadPoolExecutor:
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(max(1, threads() - 1), thread_name_prefix="derods-rods")
    return _pool


def _forget_workers() -> None:
    """In a forked child: the parent's worker threads are not there; make new ones."""
    global _pool
    _pool = None


os.register_at_fork(after_in_child=_forget_workers)
