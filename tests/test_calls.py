"""derods/_numba/calls.py: a kernel called through Bound gives what numba's dispatcher gives,
for the same argument objects call after call and for new ones."""

from typing import NamedTuple

import numba as nb
import numpy as np

from derods._numba.calls import KEEP, Bound


class Pair(NamedTuple):
    a: np.ndarray
    b: np.ndarray
    w: float


@nb.njit
def _weighted_into(pair, out):
    for i in range(len(out)):
        out[i] = pair.a[i] + pair.w * pair.b[i]
    return out.sum()


def test_bound_calls_match_the_dispatcher_for_same_and_new_arguments():
    bound = Bound(_weighted_into)
    rng = np.random.default_rng(0)
    pair, out = Pair(rng.standard_normal(5), rng.standard_normal(5), 0.5), np.zeros(5)
    for _ in range(3):  # the first call dispatches, the second resolves, the third is direct
        pair.a[:] = rng.standard_normal(5)
        total = bound(pair, out)
        assert total == _weighted_into(pair, expected := np.zeros(5))
        assert np.array_equal(out, expected)
    assert len(bound._resolved) == 1
    ints, out4 = Pair(np.arange(4), np.arange(4), 2.0), np.zeros(4)  # other types: another compiled function
    for _ in range(3):
        assert bound(ints, out4) == 18.0
    kept = []
    for k in range(KEEP + 2):  # more argument sets than it keeps: the oldest are dropped
        kept.append((Pair(np.full(2, float(k)), np.ones(2), 1.0), np.zeros(2)))
        for _ in range(3):
            assert bound(*kept[-1]) == 2.0 * (k + 1)
    assert len(bound._resolved) == KEEP
