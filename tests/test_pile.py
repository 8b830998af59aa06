"""The pile benchmark (derods/bench/pile.py, ``derods bench pile``): cables dropped into a
heap, touching the floor, one another and themselves with friction, at a size that runs in
a second (4 cables x 11 vertices)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from derods.__main__ import main
from derods.bench import pile


def test_layout_stacks_layers_of_parallel_cables_clear_of_one_another():
    case = pile.PileCase(cables=10, vertices=11)
    xs = pile.layout(case)
    assert len(xs) == 10 and all(x.shape == (11, 3) for x in xs)
    # 4 per layer (ceil(sqrt(10))): the third layer holds two; layers 2.5 diameters apart.
    heights = sorted({round(float(x[0, 2]), 6) for x in xs})
    assert np.allclose(np.diff(heights), pile.LAYER_GAP) and len(heights) == 3
    pts = np.concatenate(xs)
    owner = np.repeat(np.arange(10), 11)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)[owner[:, None] != owner[None]]
    assert d.min() > 4 * pile.RADIUS  # no cable starts touching another


def test_a_small_pile_comes_to_rest_in_a_heap(capsys):
    assert main(["bench", "pile", "--cables", "4", "--vertices", "11", "--seconds", "1", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["case"] == "pile" and rec["cables"] == 4 and rec["vertices"] == 11
    assert rec["stable"] and rec["steps"] == 120 and rec["note"] == ""
    # Two layers of two, resting on one another: the top vertex one diameter above the lower
    # layer's centres, nothing sunk by more than a radius after the impacts.
    assert rec["heap_height"] == pytest.approx(3 * pile.RADIUS, abs=0.3 * pile.RADIUS)
    assert rec["penetration"] < pile.RADIUS and rec["contacts"] > 0
    assert rec["max_speed"] < 0.05
    assert rec["ms_per_frame"] == pytest.approx(rec["us_per_step"] / 1e3 * 2)  # dt = 1/120 s: 2 steps a frame
    assert rec["late_ms_per_frame"] > 0 and rec["cpu_s"] > 0
    assert rec["backend"] == "der" and rec["solver_iterations"] is None


def test_the_same_pile_runs_on_mujocos_flexcomps(capsys):
    """``--backend flex``: the cables as MuJoCo's own 1D flexcomps, the same layout, material,
    friction and damping, stepped by mj_step; the record says how MuJoCo's solver fared
    and that the flexcomps do not touch themselves. Two layers of two come to rest on
    one another as derods' do (the test above)."""
    assert main(["bench", "pile", "--cables", "4", "--vertices", "11", "--seconds", "1", "--backend", "flex",
                 "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["backend"] == "flex" and rec["mode"] == "native" and rec["stable"] and rec["steps"] == 120
    assert rec["heap_height"] == pytest.approx(3 * pile.RADIUS, abs=0.3 * pile.RADIUS)
    assert rec["penetration"] < pile.RADIUS and rec["contacts"] > 0 and rec["max_speed"] < 0.05
    its = rec["solver_iterations"]
    assert its["solver"] == "newton" and its["cap"] == 100 and 1 <= its["median"] <= its["max"] < its["cap"]
    assert its["at_cap"] == 0 and "without self-contact" in rec["note"]
    assert "newton solver" in pile.format_record(rec)


def test_speculative_contacts_keep_landing_cables_out_of_one_another(capsys):
    """Nine cables in three layers land at up to 1.2 m/s, 10 mm a step of 1/120 s: found
    only once inside, they sink into one another by up to 2 r (11 mm measured) with no
    margin. With a margin of r (speculative rows, solved by the conjugate-gradient path
    of the contact solve: hundreds of rod-rod rows) no contact is ever deeper than r / 5
    (0.55 mm measured) and the heap comes to rest three diameters high, as laid out."""
    recs = []
    for margin in (0.0, pile.RADIUS):
        assert main(["bench", "pile", "--cables", "9", "--seconds", "1", "--margin", str(margin), "--json"]) == 0
        recs.append(json.loads(capsys.readouterr().out))
    bare, speculative = recs
    assert bare["stable"] and bare["penetration_max"] > pile.RADIUS
    assert speculative["stable"] and speculative["margin"] == pile.RADIUS
    assert speculative["penetration_max"] < 0.2 * pile.RADIUS
    assert speculative["heap_height"] == pytest.approx(5 * pile.RADIUS, abs=0.3 * pile.RADIUS)
    assert speculative["max_speed"] < 0.01


def test_speed_sized_margins_settle_the_heap_at_the_cost_of_none(capsys):
    """``--speculative``: margins sized by each cable's speed (ContactParams(speculative=True))
    instead of none. Measured at 9 cables: the deepest contact 5.16 mm against 11.02 (a
    landing cable is still found up to r inside another once), 0.28 against 0.77 mm once the
    heap formed, and the heap comes to rest three diameters high (fastest vertex 4e-4
    against 0.16 m/s) for 13.5 against 12.0 ms a frame (the margin r of the test above:
    31 ms)."""
    recs = []
    for flags in ([], ["--speculative"]):
        assert main(["bench", "pile", "--cables", "9", "--seconds", "1", "--json"] + flags) == 0
        recs.append(json.loads(capsys.readouterr().out))
    bare, speed = recs
    assert not bare["speculative"] and speed["speculative"] and speed["stable"]
    assert speed["penetration_max"] < 0.6 * bare["penetration_max"]
    assert speed["penetration"] < 0.1 * pile.RADIUS < bare["penetration"]
    assert speed["heap_height"] == pytest.approx(5 * pile.RADIUS, abs=0.3 * pile.RADIUS)
    assert speed["max_speed"] < 0.01 < bare["max_speed"]


def test_left_out_self_contacts_have_no_rows():
    """The cables' edges two apart touch (r = l / 2) and are left out after MuJoCo's
    collision (self_reach). MuJoCo's constraint builder skips an excluded contact but keeps
    the row address of its first pass: measured 328 such stale addresses among 9 landing
    cables, and the speculative correction wrote through them into other contacts' rows
    (past nefc: a crash). Every left-out contact has none, every other's rows exist."""
    world = pile.build(pile.PileCase(cables=9, seconds=1.0, margin=pile.RADIUS))
    d = world.data
    left_out = 0
    for _ in range(30):  # the lowest layer lands at step 15
        world.step()
        con = d.contact
        excluded = con.exclude[:d.ncon] != 0
        left_out += int(excluded.sum())
        assert np.all(con.efc_address[:d.ncon][excluded] == -1)
        assert np.all(con.efc_address[:d.ncon][~excluded] < d.nefc)
    assert left_out > 0


def test_a_run_stopped_by_its_budget_says_so():
    rec = pile.run(pile.PileCase(cables=2, vertices=5, seconds=1.0, max_wall_s=0.0))
    assert rec["stable"] and rec["steps"] == 1 and "stopped after 1 of 120 steps" in rec["note"]
    assert rec["late_ms_per_frame"] is None and rec["penetration"] is None
    assert "stopped before the second half" in pile.format_record(rec)


def test_pile_options_are_checked(capsys):
    assert main(["bench", "pile", "--repeats", "2"]) == 2
    assert main(["bench", "cantilever", "--cables", "3"]) == 2
    assert main(["bench", "cantilever", "--margin", "0.01"]) == 2
    assert main(["bench", "cantilever", "--speculative"]) == 2
    assert main(["bench", "pile", "--backend", "cable"]) == 2
    assert main(["bench", "pile", "--backend", "flex", "--speculative"]) == 2
    err = capsys.readouterr().err
    assert "--repeats is not an option of the pile case" in err and "--cables is an option of the pile case only" in err
    assert "backend must be one of ('der', 'flex') for the pile case, got 'cable'" in err
    assert "the flex pile runs with neither" in err
    assert "--margin is an option of the pile case only" in err
    with pytest.raises(ValueError, match="cables must be an integer >= 1"):
        pile.PileCase(cables=0)
    with pytest.raises(ValueError, match="margin must be finite and >= 0"):
        pile.PileCase(margin=-1e-3)
    with pytest.raises(ValueError, match="flex_solver must be one of"):
        pile.PileCase(backend="flex", flex_solver="dense")
    with pytest.raises(ValueError, match="flex_solver is the flex pile's option"):
        pile.PileCase(flex_solver="cg")
