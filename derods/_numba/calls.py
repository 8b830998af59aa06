"""Calls of a compiled kernel that get the same argument objects step after step, without
numba typing them again at every call.

numba types each argument of every call before it finds the compiled code for them: a
bare array costs it ~0.02 us, but a named tuple ~0.4 us plus ~0.07 us per field, so the
step's bundles (:class:`derods.step.RodSet`'s 23 arrays, the frames, the terms, the
implicit system) cost ~3 us per call of the rod step and as much again for the implicit
solve: a fifth of a small world's step (26 us for a 20-edge cantilever, measured). The
bundles are immutable and an array's dtype, dimensions and layout never change, so the
same argument objects have the same types: :class:`Bound` resolves the compiled function
for them once and then calls it directly while they come back; any other arguments go
through numba's dispatcher as usual. The contact stage's rows are views of MuJoCo's data
made afresh each step, typed by MuJoCo: it keys them by the data (:meth:`Bound.keyed`).
"""

from __future__ import annotations

#: Argument sets a Bound keeps resolved (a world's step, its alpha mode's second
#: evaluation point, a few worlds at once); the oldest is dropped beyond.
KEEP = 8


class Bound:
    """``kernel(*args)`` (a numba dispatcher) with its compiled function remembered for the
    argument objects of the calls that repeat them (held, so their ids stay theirs)."""

    def __init__(self, kernel):
        self.kernel = kernel
        self._resolved = {}  # ids of the arguments -> (the arguments, the compiled function)
        self._seen = set()  # ids of recent calls' arguments, resolved when they come again

    def __call__(self, *args):
        return self.keyed(args, args)

    def keyed(self, key, args):
        """``kernel(*args)``, its compiled function remembered for the objects of ``key``
        (a tuple): the arguments themselves, or in place of an argument made afresh for
        each call, an object that fixes its type (MuJoCo's data, for a bundle of its views:
        their dtypes, dimensions and layouts are MuJoCo's, whatever their lengths)."""
        ids = tuple(map(id, key))
        hit = self._resolved.get(ids)
        if hit is not None:
            return hit[1](*args)
        if ids in self._seen:
            if len(self._resolved) >= KEEP:
                self._resolved.pop(next(iter(self._resolved)))
            sig = tuple(self.kernel.typeof_pyval(a) for a in args)
            entry = self.kernel.compile(sig)
            self._resolved[ids] = (key, entry)
            return entry(*args)
        if len(self._seen) >= 4 * KEEP:
            self._seen.clear()
        self._seen.add(ids)
        return self.kernel(*args)
