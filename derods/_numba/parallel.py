"""Rods in parallel: the per-rod kernels of a step, run on threads for a world of many rods.

In three stages of a step every rod's work is its own: its terms and band
(:func:`derods._numba.step.rods_step`), its diagonal block of the implicit matrix, which
is block diagonal over rods, with its factor and solves
(:func:`derods._numba.implicit.unconstrained_step`), and its strain limit
(:func:`derods._numba.projection.limit_strain`). Each has a chunk kernel beside it
(``rods_chunk``, ``unconstrained_chunk``, ``limit_chunk``) that runs the same code for one
:class:`Split` chunk, a run of whole rods, on views of the world's arrays, and releases the
GIL. A world whose rods are one chunk calls the kernels as they are (:func:`kernel`); a
world of more chunks calls the chunk kernels through a :class:`Runner`, the first chunk in
the stepping thread and the others on worker threads. Each rod's arithmetic is the same
either way, so the results are the same to the bit (tests/test_parallel.py holds a world
of many rods to that).

Why Python threads rather than numba's ``parallel=True``, measured on the 2-core VM: the
same kernels with ``prange`` over the chunks took 11 s more to compile from scratch (numba
compiles each parallel loop's body again, with every kernel it calls: 5.9 s for the rods'
alone, where a second plain entry point costs 1.3 s), and with the machine's other core
busy, a parallel region waited a scheduler tick (4-8 ms) for GNU OpenMP's spinning
threads, where a chunk handed to a thread through a queue waits for a core without
spinning on the other. Nor does a thread pool depend on numba's threading layer (no lock
for its workqueue, no OpenMP rule against forking).

A hand-off costs tens of microseconds a kernel call, more than a small world's whole rod
stage: :func:`plan` gives a world threads only when each chunk holds at least
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

#: Fewest vertices a chunk of rods takes for a world to step on threads. Measured on the
#: 2-core VM (benchmarks/bench_parallel.py, sizes): straight rods of 32 vertices hanging,
#: the cheapest rods a step has, stepped 9 % slower on two threads at 32 rods (1024
#: vertices), 7 % faster at 64 and 22 % at 128; a hand-off costs ~45 us a kernel call.
MIN_CHUNK_VERTICES = 1024

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


def kernel(whole, chunk, split: Split, bundle: bool = False, combine=None, resolve: bool = True):
    """How a world calls a per-rod kernel: ``whole`` (its arguments as they are) when
    ``split`` is one chunk, else a :class:`Runner` of ``chunk`` over the chunks, their
    results combined by ``combine``. resolve: call through a
    :class:`derods._numba.calls.Bound` (for arguments that come back step after step; a
    call with arrays made afresh goes to the dispatcher)."""
    if not split.parallel:
        return Bound(whole) if resolve else whole
    return Runner(chunk, split, bundle, combine, resolve)


class Runner:
    """A chunk kernel (a numba dispatcher that releases the GIL, whose last argument is a
    chunk: a one-chunk Split if ``bundle``, else its ``rods`` (2,)) called once per chunk of
    ``split``: the first chunk in the calling thread, the others on worker threads.
    Returns ``combine`` of the chunks' results in order (None without it); if a chunk
    raised, it waits for the others (they write the same arrays) and raises the first
    chunk's exception. resolve: as :func:`kernel`'s."""

    def __init__(self, chunk, split: Split, bundle: bool = False, combine=None, resolve: bool = True):
        self.parts = [p if bundle else p.rods for p in split.parts()]
        # A Bound each: no bookkeeping shared between threads.
        self.calls = [Bound(chunk) if resolve else chunk for _ in self.parts]
        self.combine = combine

    def __call__(self, *args):
        pool = workers()
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
        return None if self.combine is None else self.combine(results)


def first_bad(results: list) -> int:
    """The rod step's result over chunks: the first rod strained too far, else -1."""
    return next((r for r in results if r >= 0), -1)


def totals(results: list) -> tuple:
    """The strain limit's result over chunks: (rods projected, rods left), summed."""
    return tuple(int(sum(r[k] for r in results)) for k in range(2))


def workers() -> ThreadPoolExecutor:
    """The worker threads (threads() - 1 of them, made at first use)."""
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(max(1, threads() - 1), thread_name_prefix="derods-rods")
    return _pool


def _forget_workers() -> None:
    """In a forked child: the parent's worker threads are not there; make new ones."""
    global _pool
    _pool = None


os.register_at_fork(after_in_child=_forget_workers)
