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


def _lying(n_rods: int) -> derods.World:
    """Rods of 12 vertices dropped side by side onto the floor, every third one clamped at
    both ends with a twist (the blocks' twist terms) and sagging onto it, each rod its own
    block of contact rows."""
    mat = derods.Material(young=1e7, radius=0.005)
    world = derods.World(scenes.path("floor"), dt=1e-2, mass_damping=1.0)
    for i in range(n_rods):
        if i % 3 == 1:
            x = shapes.straight(0.3, 11, start=(0.0, 0.03 * i, 0.006))
            world.add_rod(derods.Rod(x, mat, boundary=TwistBoundary("clamped", 0.0, 1.0)), f"r{i}", start="clamp",
                          end="clamp")
        else:
            x = shapes.straight(0.3, 11, start=(0.0, 0.03 * i, 0.02 + 0.002 * i))
            world.add_rod(derods.Rod(x, mat), f"r{i}")
    world.compile()
    return world


def test_contact_blocks_on_two_threads_give_the_one_thread_step_to_the_bit(monkeypatch):
    """Past SPLIT_MIN_ROWS rows a step's blocks of rods are solved in two runs, one on a
    worker thread (derods.sim.contact.ContactStep._solve_threaded): each block's arithmetic
    is the same, so the positions are the same to the bit as one call's, and the second run
    did take blocks."""
    from derods.sim import contact

    splits = []
    split = contact.split_blocks
    monkeypatch.setattr(contact, "split_blocks", lambda *a: splits.append(split(*a)) or splits[-1])
    one, two = _lying(8), _lying(8)
    one._step.contact._threaded = False
    two._step.contact._threaded = True
    two._step.contact.split_min_rows = 1
    for _ in range(STEPS):
        one.step()
        two.step()
    assert one.data.ncon > 8 and any(s is not None for s in splits)
    np.testing.assert_array_equal(one.all_positions(), two.all_positions())
    np.testing.assert_array_equal(one.data.efc_force[:one.data.nefc], two.data.efc_force[:two.data.nefc])


def test_blocks_split_where_the_work_halves_and_only_when_worth_it():
    from derods.sim.contact import SPLIT_MIN_ROWS, split_blocks
    rows = SPLIT_MIN_ROWS // 4
    even = np.arange(5) * (96 + rows)  # four equal blocks
    assert split_blocks(np.arange(5) * 96, even - np.arange(5) * 96) == 2
    assert split_blocks(np.array([0, 96]), np.array([0, 2 * SPLIT_MIN_ROWS])) is None  # one block
    assert split_blocks(np.arange(5) * 96, np.arange(5) * 10) is None  # too few rows
    lopsided = np.array([0, 10 * SPLIT_MIN_ROWS, 10 * SPLIT_MIN_ROWS + 10])  # one block holds the work
    assert split_blocks(np.array([0, 96, 192]), lopsided) is None
