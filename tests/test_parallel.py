"""derods/_numba/parallel.py: a world stepped with its rods in chunks on threads gives the
serial step's positions to the bit, and a world takes threads only when large.

Each chunk runs its rods in order doing for them what one chunk of all rods does (their
terms, their block of the implicit matrix and its solves, their strain limit), so no
floating-point operation changes order: the comparison is exact, not within a tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

import derods
from derods import scenes, shapes
from derods._numba import parallel
from derods.sim.divergence import DivergenceError
from derods.twist import TwistBoundary

#: Steps the worlds are compared over: long enough for the dropped rods to land (contacts,
#: the strain limit's projections) and the held ones to swing.
STEPS = 40


def _many_rods(mode: str = "implicit") -> derods.World:
    """Thirteen rods of every kind a step treats apart, in ``mode``: curled strands (the
    Newton twist solve), straight rods clamped at both ends with a twist (the rank-one twist
    terms of the implicit system), free rods dropped on the floor (contacts, strain limit)
    and a ring (the wider band)."""
    mat = derods.Material(young=1e7, radius=0.005)
    world = derods.World(scenes.path("floor"), dt=1e-2, mass_damping=1.0, mode=mode)
    for i in range(4):
        world.add_rod(derods.Rod(shapes.helix(0.03, 0.02, 1.0, 12, start=(0.3 * i, 0.5, 0.5)), mat), f"curl{i}",
                      start="clamp")
    for i in range(4):
        x = shapes.straight(0.25, 10, start=(0.3 * i, -0.5, 0.4))
        world.add_rod(derods.Rod(x, mat, boundary=TwistBoundary("clamped", 0.0, 1.0 + i)), f"twisted{i}",
                      start="clamp", end="clamp")
    for i in range(4):
        x = shapes.straight(0.4, 14, start=(0.3 * i - 0.2, 0.0, 0.05 + 0.02 * i), direction=(1.0, 0.2 * i, 0.0))
        world.add_rod(derods.Rod(x, mat), f"dropped{i}")
    if mode != "projection":  # which takes open rods only
        world.add_rod(derods.Rod(shapes.circle(0.05, 12, center=(0.0, -1.0, 0.1)), mat, closed=True,
                                 natural_curvature=False, boundary=TwistBoundary("ring", total_twist=1.0)), "ring")
    world.compile()
    return world


def _state(world: derods.World) -> np.ndarray:
    return np.concatenate([world.data.qpos, world.data.qvel, world._step.frames.theta])


def _run(n_chunks: int, mode: str) -> np.ndarray:
    world = _many_rods(mode)
    st = world._step
    st.use_split(parallel.split(st.rods.v_off, st.layout.dof_off, st.rod_tw, n_chunks))
    assert st.split.parallel == (n_chunks > 1)
    world.step(STEPS)
    return _state(world)


@pytest.mark.parametrize("mode", ["implicit", "alpha", "projection"])
def test_parallel_step_gives_the_serial_positions_to_the_bit(mode):
    """Two and three chunks (more than this machine may have threads: they queue) against
    one, over steps with contacts, strain limiting, twist terms and Newton twist
    solves, in every mode that takes the parallel kernels."""
    serial = _run(1, mode)
    for n_chunks in (2, 3):
        assert _run(n_chunks, mode).tobytes() == serial.tobytes(), f"{n_chunks} chunks"


def test_split_cuts_between_rods_with_their_dofs_and_twist_terms():
    world = _many_rods()
    st = world._step
    s = parallel.split(st.rods.v_off, st.layout.dof_off, st.rod_tw, 3)
    assert s.rods[0] == 0 and s.rods[-1] == st.rods.n_rods and np.all(np.diff(s.rods) > 0)
    assert np.array_equal(s.dofs, st.layout.dof_off[s.rods])
    assert len(st.rod_tw) == 5  # the twisted rods and the ring carry the twist terms
    for c in range(len(s.rods) - 1):
        terms = st.rod_tw[s.twists[c]:s.twists[c + 1]]
        assert np.all((terms >= s.rods[c]) & (terms < s.rods[c + 1]))
    assert s.twists[-1] == len(st.rod_tw)


def test_a_world_takes_threads_only_when_each_chunk_is_large(monkeypatch):
    """One rod never splits; a few short rods stay serial (the launch would cost more than
    it saves); many rods split one chunk a thread, balanced by vertices."""
    monkeypatch.setattr(parallel, "threads", lambda: 2)

    def plan(n_rods, nv):
        v_off = np.arange(n_rods + 1) * nv
        return parallel.plan(v_off, 3 * v_off, np.zeros(0, dtype=np.int64))

    assert not plan(1, 100_000).parallel
    assert not plan(4, 32).parallel
    assert not plan(2 * parallel.MIN_CHUNK_VERTICES // 32 - 1, 32).parallel
    assert plan(2 * parallel.MIN_CHUNK_VERTICES // 32, 32).parallel
    big = plan(1000, 32)
    assert big.parallel and np.array_equal(big.rods, [0, 500, 1000])
    monkeypatch.setattr(parallel, "threads", lambda: 1)  # NUMBA_NUM_THREADS=1
    assert not plan(1000, 32).parallel


def test_a_system_not_positive_definite_is_reported_from_a_worker_thread():
    """The last chunk's solve, on a worker thread, raises the serial kernel's ValueError in
    the stepping thread (once the other chunks are done), which the step turns into its
    diagnosis."""
    world = _many_rods()
    st = world._step
    st.use_split(parallel.split(st.rods.v_off, st.layout.dof_off, st.rod_tw, 3))
    st.system.arrays.mass[-3:] = -1.0  # the last rod's last vertex: only the last chunk fails
    with pytest.raises(DivergenceError, match="not positive definite"):
        world.step()
