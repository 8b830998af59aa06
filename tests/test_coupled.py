"""The coupled step of rods, their holders and their contacts (derods/sim/coupled.py): its
compiled calls, keyed on the step's own objects."""

from __future__ import annotations

import collections

import pytest

from derods._numba.calls import Bound
from derods.bench import held

#: Scenes that reach every keyed call of the coupled step: a cart dragging a cable on the
#: floor and one drawing it over a ledge (slides: no arcs), a free box landing with its rod
#: (turning: arcs, and rows of the held edge on its own box), held by a pin or a clamp.
SCENES = [("drag", "slide", 5e-3, 40), ("edge", "slide", 5e-3, 40), ("land", "free", 1e-3, 150)]
#: The kernels the coupled step calls through Bound.
KEYED = {"sm_solve_columns_into", "bordered_rows", "row_weights", "newton", "row_forces_into"}


@pytest.mark.parametrize("end", ["pin", "clamp"])
def test_every_keyed_call_gets_the_types_it_was_resolved_for(monkeypatch, end):
    """The coupled step calls its kernels through Bound, which calls a resolved compiled
    function directly: arguments of other types than it was resolved for would be read as
    those types. It keys the calls on MuJoCo's data and its own buffers, standing in for
    arguments made afresh each step (the rows' bundle, weights and multipliers the kernels
    allocate). Checked at every call that reuses a resolution, in scenes that reach each
    call site many times: the arguments' types resolve to the very function called."""
    checked = collections.Counter()
    keyed = Bound.keyed

    def checked_keyed(self, key, args):
        hit = self._resolved.get(tuple(map(id, key)))
        if hit is not None:
            sig = tuple(self.kernel.typeof_pyval(a) for a in args)
            assert self.kernel.compile(sig) is hit[1], f"{self.kernel.__name__} called with {sig}"
            checked[self.kernel.__name__] += 1
        return keyed(self, key, args)

    monkeypatch.setattr(Bound, "keyed", checked_keyed)
    for scenario, holder, dt, steps in SCENES:
        held.build(held.Case(scenario, holder, mass=1.0, end=end, dt=dt)).world.step(steps)
    missed = {name for name in KEYED if checked[name] < 10}
    assert not missed, f"calls not checked (enough): {missed}, counts {dict(checked)}"
