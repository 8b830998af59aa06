"""Contact solved in the implicit metric (derods/sim/contact.py, derods/_numba/contact.py; the rows and their
solve taken apart through tests/oracles.py)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import scipy.optimize
from oracles import ContactRows, a_matvec, contact_solve, implicit_system, random_band

import derods
from derods import scenes, shapes
from derods.sim import contact
from derods import World
from derods._numba import row_weights as _row_weights
from derods._numba.contact_rows import FAR_DENSE_MAX


def small_problem(rng, n_vertices=6, n_rows=7, n_far=0):
    n = 3 * n_vertices
    system = implicit_system(1e-2, np.array([0, n]), [random_band(rng, n)], [(rng.normal(size=n), 2.0)],
                             rng.uniform(0.5, 1.5, size=n), 0.3, 1e-3)
    col0 = rng.integers(0, n - 6, size=n_rows)
    jw = np.zeros((n_rows, 9))
    jw[:, :6] = rng.normal(size=(n_rows, 6))
    jf = None
    if n_far:
        jf = np.zeros((n_far, n))
        for r in range(n_far):  # a contact between the first and the last vertex
            jf[r, :3], jf[r, -3:] = rng.normal(size=3), rng.normal(size=3)
    k = n_rows + n_far
    rows = ContactRows(col0, jw, rng.normal(size=k) * 5, rng.uniform(1, 50, size=k), np.arange(k), jf=jf)
    return system, rows, rng.normal(size=n)


@pytest.mark.parametrize("n_rows,n_far", [(7, 0), (7, 3), (0, 4), (7, FAR_DENSE_MAX + 16)])
def test_newton_finds_the_minimum_of_mujocos_primal_problem(n_rows, n_far):
    """min 1/2 (a - a0)^T A (a - a0) + sum 1/2 D_i min(J_i a - aref_i, 0)^2, compared with a
    general-purpose minimizer, and its optimality condition holds to round-off; with
    rows between distant vertices (self-contact) handled as a low-rank update, also when
    every row is one (a self-contact and nothing else: B must still be factored), and past
    FAR_DENSE_MAX of them by conjugate gradients (a pile's rod-rod rows). There, 87 rows on
    18 dofs, BFGS stops 1e-4 short (measured); the reference is then the dense active-set
    solve: the problem is quadratic once its active rows are known."""
    rng = np.random.default_rng(0)
    system, rows, a0 = small_problem(rng, n_rows=n_rows, n_far=n_far)
    a, lam, iters = contact_solve(system, a0, rows)
    assert np.all(lam >= 0) and np.any(lam > 0) and np.any(lam == 0)

    def f(x):
        r = np.minimum(rows.apply(x) - rows.aref, 0.0)
        return 0.5 * (x - a0) @ a_matvec(system, x - a0) + 0.5 * np.sum(rows.d * r * r)

    if n_far <= FAR_DENSE_MAX:
        ref = scipy.optimize.minimize(f, a0, method="BFGS", options={"gtol": 1e-12, "maxiter": 10000}).x
    else:
        ref = _active_set_minimum(system, rows, a0, a0)
    np.testing.assert_allclose(a, ref, rtol=1e-5, atol=1e-7 * np.abs(ref).max())
    grad = a_matvec(system, a - a0) - rows.transpose_apply(lam, system.n)
    # Newton stops once the gradient is below TOL = 1e-10 of its force scale, max |M a0| +
    # max |D aref| (derods/_numba/contact_newton.py): checked to ten times that. (Until the
    # far rows' blocks entered CG's preconditioner, 2026-12-05, the 80-far-row case happened
    # to stop within 1e-9 of max |A a0| too; it now stops at 1.1e-9 of it, 1.5e-11 of the scale.)
    scale = np.abs(a_matvec(system, a0)).max() + np.abs(rows.d * rows.aref).max()
    np.testing.assert_allclose(grad, 0.0, atol=1e-9 * scale)
    assert iters < 30


def _active_set_minimum(system, rows, a0, start):
    """The minimum of the contact problem by dense active-set iteration from ``start``:
    with the active rows J_a fixed, (A + J_a^T D J_a) a = A a0 + J_a^T D aref; repeated until
    the active set is that of its own solution."""
    n = system.n
    a_dense = np.stack([a_matvec(system, e) for e in np.eye(n)], axis=1)
    jac = np.stack([rows.apply(e) for e in np.eye(n)], axis=1)
    a, active = start, None
    for _ in range(100):
        now = jac @ a - rows.aref < 0
        if active is not None and np.array_equal(now, active):
            return a
        active = now
        jd = jac[active].T * rows.d[active]
        a = np.linalg.solve(a_dense + jd @ jac[active], a_dense @ a0 + jd @ rows.aref[active])
    raise AssertionError("the active set did not settle")


def test_far_rows_weights_row_by_row_equal_the_dense_solves():
    """Past FAR_DENSE_MAX far rows, diag(J A^-1 J^T) is taken row by row from the band of
    A^-1 (rows between two rods, which meet nowhere in A^-1) or by a solve per row (a rod
    touching itself far along); both equal the dense block of solves to round-off (1e-12
    relative: a dozen products either way), twist terms included."""
    rng = np.random.default_rng(3)
    sizes = (30, 24, 27)
    offsets = np.concatenate(([0], np.cumsum(sizes)))
    n = int(offsets[-1])
    bands = [random_band(rng, m) for m in sizes]
    twist = [(rng.normal(size=sizes[0]), 2.0), None, (rng.normal(size=sizes[2]), 0.7)]
    system = implicit_system(1e-2, offsets, bands, twist, rng.uniform(0.5, 1.5, size=n), 0.3, 1e-3)
    n_far = FAR_DENSE_MAX + 20
    jf = np.zeros((n_far, n))
    for r in range(n_far):
        i, j = rng.choice(3, size=2, replace=r % 5 == 0)  # one row in five a rod on itself
        vi = offsets[i] + 3 * rng.integers(0, sizes[i] // 3 - 1)
        vj = offsets[j] + 3 * rng.integers(0, sizes[j] // 3 - 1)
        if i == j and abs(vi - vj) < 12:
            vj = offsets[j] + (vi - offsets[j] + 15) % (sizes[j] - 5)
        jf[r, vi:vi + 6] = rng.normal(size=6)  # an edge of each: its two vertices
        jf[r, vj:vj + 6] += rng.normal(size=6)
    rows = ContactRows(np.zeros(0, dtype=np.int64), np.zeros((0, 9)), np.zeros(n_far), np.ones(n_far),
                       np.arange(n_far), jf=jf).rows(n)
    rod_of_dof = np.searchsorted(offsets, np.arange(n), side="right") - 1
    by_row = _row_weights.delassus_diagonal(system.arrays, rows, rod_of_dof)
    dense = _row_weights.delassus_diagonal(system.arrays, rows, np.zeros(0, dtype=np.int64))
    a_inv = np.linalg.inv(np.stack([a_matvec(system, e) for e in np.eye(n)], axis=1))
    np.testing.assert_allclose(dense, np.einsum("ij,jk,ik->i", jf, a_inv, jf), rtol=1e-9)
    np.testing.assert_allclose(by_row, dense, rtol=1e-12)


def test_rows_band_and_products_match_dense_jacobian():
    rng = np.random.default_rng(1)
    system, rows, _ = small_problem(rng, n_far=2)
    n = system.n
    dense = np.zeros((len(rows), n))
    for i in range(rows.n_banded):
        w = min(9, n - rows.col0[i])
        dense[i, rows.col0[i]: rows.col0[i] + w] = rows.jw[i, :w]
    dense[rows.n_banded:] = rows.jf
    x = rng.normal(size=n)
    np.testing.assert_allclose(rows.apply(x), dense @ x, rtol=1e-12)
    lam = rng.uniform(size=len(rows))
    np.testing.assert_allclose(rows.transpose_apply(lam, n), dense.T @ lam, rtol=1e-12, atol=1e-14)
    band = rows.band(rows.d, n)
    kb = rows.n_banded
    jtdj = dense[:kb].T @ (rows.d[:kb, None] * dense[:kb])
    for d in range(9):
        np.testing.assert_allclose(band[d, : n - d], np.diag(jtdj, -d), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("dt", [2e-3, 1e-2])
def test_rod_resting_on_the_floor_is_held_by_its_weight(dt):
    """At rest the contact forces carry the rod's weight exactly and no net sideways force."""
    mat = derods.Material(young=1e7)
    rod = derods.Rod(shapes.straight(0.8, 16, start=(-0.4, 0, 0.05)), mat)
    w = World(scenes.path("floor"), dt=dt, mass_damping=2.0)
    w.add_rod(rod)
    w.step(int(1.0 / dt))
    assert np.abs(w.velocities()).max() < 1e-6
    f = w.contact_force().sum(axis=0)
    weight = mat.line_density * rod.length * 9.81
    np.testing.assert_allclose(f[2], weight, rtol=1e-6)
    np.testing.assert_allclose(f[:2], 0.0, atol=1e-9 * weight)
    # Resting penetration far below the radius (measured 0.02 mm at n = 50).
    assert w.positions()[:, 2].min() > mat.radius - 1e-3


def _box_on_cable(box_mass: float, trees: bool, monkeypatch, links: int = 0,
                  cone: str = "pyramidal") -> tuple[float, float]:
    """A box (10 x 10 x 4 cm) on a free joint let down onto a cable (r = 6 mm) lying on the
    floor; after 2 s: (the box's bottom, the cable's top) [m]. links: a chain of that many
    hinged 10 g balls on the box (centred on their hinges, so that turning they move no
    mass across the cable, on which the box balances; touching nothing), its tree 6 +
    links dofs. cone: MuJoCo's friction cone."""
    if not trees:
        init = contact.ContactStep.__init__

        def without_trees(self, *args, **kwargs):
            init(self, *args, **kwargs)
            self.bodies = False

        monkeypatch.setattr(contact.ContactStep, "__init__", without_trees)
    chain = ""
    for i in range(links):
        chain += (f'<body pos="0 {0.01 if i else 0} {0 if i else 0.03}"><joint type="hinge" '
                  f'axis="{i % 2} {1 - i % 2} 0" damping="0.01"/><geom type="sphere" size="0.004" mass="0.01" '
                  'contype="0" conaffinity="0"/>')
    chain += "</body>" * links
    xml = f"""<mujoco><option timestep="0.002" integrator="implicitfast" cone="{cone}"/><worldbody>
      <geom name="floor" type="plane" size="2 2 0.1"/>
      <body name="box" pos="0 0 0.05"><freejoint/><geom type="box" size="0.05 0.05 0.02" mass="{box_mass}"/>
      {chain}</body>
    </worldbody></mujoco>"""
    world = World(mujoco.MjSpec.from_string(xml), dt=2e-3, contact=derods.ContactParams(friction=1.0))
    r = 0.006
    x = shapes.straight(0.6, 40)
    x = np.stack([np.zeros(len(x)), x[:, 0] - x[:, 0].mean(), np.full(len(x), r + 1e-4)], axis=1)
    world.add_rod(derods.Rod(x, derods.Material(young=2e7, radius=r, density=1100.0)), "cable")
    world.compile()
    world.data.qpos[2] = 2 * r + 0.02 + 1e-3  # the box's bottom 1 mm above the cable
    world.step(1000)
    return world.data.qpos[2] - 0.02, 2 * r


#: How far the box may rest into the 6 mm cable: a quarter of its radius with pyramidal
#: cones (measured 0.86 mm), half with elliptic ones (measured 1.56 mm): MuJoCo's elliptic
#: normal row is softer than derods' pyramid rows at mu = 1. Both keep MuJoCo's impedance
#: R / diagA, and MuJoCo's diagA of a pyramid row is 2 mu^2 (1 + mu^2) times the normal's,
#: its true J A^-1 J^T (1 + mu^2) times: derods' pyramid rows weigh 2 mu^2 times MuJoCo's
#: own (stiffer above mu = 0.71, softer below; a rod resting on a floor at mu = 1: 0.011 mm
#: deep, elliptic 0.030 mm; in MuJoCo a sphere sinks 0.367 mm with either cone at mu = 1).
SINK = {"pyramidal": 0.006 / 4, "elliptic": 0.006 / 2}


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_box_rests_on_a_cable(monkeypatch, cone):
    """The box's dofs join the contact solve where it touches the cable, so the cable
    carries a 1 kg box: it rests within SINK of the cable's top (MuJoCo's soft contact
    under 10 N), with either cone."""
    bottom, top = _box_on_cable(1.0, True, monkeypatch, cone=cone)
    assert bottom > top - SINK[cone]


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_tree_larger_than_the_band_rests_on_a_cable_as_its_border(monkeypatch, cone):
    """The same box carrying a chain of six hinged balls: its tree has 12 dofs, more than
    the band's 9, and joins the contact solve as the band's border (Schur complement).
    It rests on the cable as the 6-dof box does (measured 0.89 mm into it; the same solve
    with a 6- or 8-dof tree as a border matches the band's to 1e-16 m); left to MuJoCo, as
    trees larger than the band were until 2026-12-05, it sank to the floor (-0.04 mm). With
    elliptic cones the border solve takes the cones too (SINK: measured 1.63 mm)."""
    bottom, top = _box_on_cable(1.0, True, monkeypatch, links=6, cone=cone)
    assert bottom > top - SINK[cone]


def test_two_large_trees_and_their_contact_join_one_border():
    """Two 12-dof trees (a 1 kg box carrying six hinged balls each) resting on one cable,
    one box also leaning on the other: both join the border at once, and the box-box
    contact (a row on border dofs only) is solved with them. Both rest on the cable within
    a quarter of its radius, and the cable carries their weight."""
    r = 0.006
    balls = "".join(f'<body pos="0 {0.01 if i else 0} {0 if i else 0.03}"><joint type="hinge" axis="{i % 2} '
                    f'{1 - i % 2} 0" damping="0.01"/><geom type="sphere" size="0.004" mass="0.01" contype="0" '
                    'conaffinity="0"/>' for i in range(6)) + "</body>" * 6
    boxes = "".join(f'<body name="box{k}" pos="0 {y} {2 * r + 0.02 + 1e-3}"><freejoint/>'
                    f'<geom type="box" size="0.05 0.05 0.02" mass="1"/>{balls}</body>'
                    for k, y in ((0, -0.06), (1, 0.0399)))
    xml = f"""<mujoco><option timestep="0.002" integrator="implicitfast"/><worldbody>
      <geom name="floor" type="plane" size="2 2 0.1"/>{boxes}</worldbody></mujoco>"""
    world = World(mujoco.MjSpec.from_string(xml), dt=2e-3, contact=derods.ContactParams(friction=1.0),
                  scene_checks=False)
    x = shapes.straight(0.6, 40)
    x = np.stack([np.zeros(len(x)), x[:, 0] - x[:, 0].mean(), np.full(len(x), r + 1e-4)], axis=1)
    world.add_rod(derods.Rod(x, derods.Material(young=2e7, radius=r, density=1100.0)), "cable")
    world.compile()
    m, d = world.model, world.data
    assert all(m.tree_dofnum[m.body_treeid[m.body(f"box{k}").id]] == 12 for k in (0, 1))
    world.step(1000)
    assert {"box0", "box1"} <= set(world.solved_bodies())
    for k in (0, 1):
        assert d.xpos[m.body(f"box{k}").id][2] - 0.02 > 2 * r - r / 4
    boxes_weight = 2 * (1.0 + 6 * 0.01) * 9.81
    cable_weight = derods.Material(young=2e7, radius=r, density=1100.0).line_density * 0.6 * 9.81
    # the floor carries the boxes through the cable, and the cable: net, the cable's weight
    floor = sum(c.normal_force for c in world.contacts() if c.geom == m.geom("floor").id)
    assert floor == pytest.approx(boxes_weight + cable_weight, rel=0.05)
    assert world.contact_force("cable").sum(axis=0)[2] == pytest.approx(cable_weight, rel=0.05)
    touching = [i for i in range(d.ncon) if {m.geom_bodyid[g] for g in d.contact[i].geom if g >= 0}
                == {m.body("box0").id, m.body("box1").id}]
    assert touching and all(d.contact[i].efc_address >= 0 for i in touching)  # the boxes lean on each other


def test_a_tree_solved_as_the_border_moves_as_in_the_band(monkeypatch):
    """The border's Schur complement is the band's elimination in another order: an 8-dof
    tree made to join as a border rests where the band puts it, to round-off."""
    banded, _ = _box_on_cable(1.0, True, monkeypatch, links=2)
    init = contact.ContactStep.__init__

    def every_tree_large(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self._large[:] = True

    monkeypatch.setattr(contact.ContactStep, "__init__", every_tree_large)
    bordered, _ = _box_on_cable(1.0, True, monkeypatch, links=2)
    assert bordered == pytest.approx(banded, abs=1e-12)


def test_left_to_mujoco_the_box_sinks_through_the_cable(monkeypatch):
    """The test above can fail: with the box's rows left to MuJoCo (its force computed for
    a bare vertex mass), the same box ends on the floor."""
    bottom, _ = _box_on_cable(1.0, False, monkeypatch)
    assert bottom < 1e-3


@pytest.mark.parametrize("mode", ["implicit", "alpha", "projection"])
def test_each_rod_contact_reports_what_the_step_applied(mode):
    """World.contacts(): a rod on a floor, a second rod across it, a free box resting on the
    second. Summed over its contacts, the forces on each rod equal World.contact_force's sum
    (the same row forces, read per contact through mj_contactForce: 1e-9 N); every floor
    contact names the world body and the floor geom, the crossing names the other rod, the
    box's contact the box's body, and the floor holds the lower rod up."""
    r = 0.004
    spec = mujoco.MjSpec.from_string(
        '<mujoco><worldbody><geom name="floor" type="plane" size="2 2 .1"/>'
        f'<body name="box" pos="0.1 0.2 {4 * r + 0.02 + 5e-4}"><freejoint/>'
        '<geom name="boxgeom" type="box" size="0.02 0.02 0.02" mass="0.2"/></body></worldbody></mujoco>')
    dt = 2e-3
    w = World(spec, dt=dt, mode=mode, scene_checks=False, contact=derods.ContactParams(rod_rod=True))
    w.add_rod(derods.Rod(shapes.straight(0.6, 30, start=(-0.3, 0.0, r)), derods.Material(young=1e7, radius=r)), "low")
    w.add_rod(derods.Rod(shapes.straight(0.6, 30, start=(0.1, -0.3, 3 * r + 5e-4), direction=(0, 1, 0)),
                         derods.Material(young=1e7, radius=r)), "high")
    w.step(int(round(0.05 / dt)))
    cs = w.contacts()
    floor, box = w.model.geom("floor").id, w.model.body("box").id
    on_floor = [c for c in cs if c.geom == floor]
    assert on_floor and all(c.body == 0 and c.other_rod is None and c.normal_force >= 0 for c in on_floor)
    for name in ("low", "high"):
        mine = [c for c in cs if c.rod == name]
        applied = sum((c.normal_force * c.normal + c.friction for c in mine), np.zeros(3))
        applied -= sum((c.normal_force * c.normal + c.friction for c in cs if c.other_rod == name and c.rod != name),
                       np.zeros(3))  # a rod-rod contact is listed once, seen from one rod
        np.testing.assert_allclose(applied, w.contact_force(name).sum(axis=0), atol=1e-9)
    assert {(c.rod, c.other_rod) for c in cs if c.other_rod is not None} & {("high", "low"), ("low", "high")}
    assert any(c.body == box and c.rod == "high" for c in cs)
    assert sum(c.normal_force for c in on_floor) > 0
    # the box's tree joined derods' solve (MuJoCo's own solve in the projection mode)
    assert w.solved_bodies() == ([] if mode == "projection" else ["box"])


@pytest.mark.parametrize("priority", [0, 2])
def test_the_rods_contact_priority_decides_whose_contact_parameters_win(priority):
    """ContactParams(priority=...) is the rods' flex priority: against a pad of priority 1,
    the default 0 takes the pad's solref and friction whole (MuJoCo's rule: the higher
    side's parameters), 2 takes the rod's."""
    spec = mujoco.MjSpec.from_string(
        '<mujoco><worldbody><geom name="pad" type="box" size="0.2 0.2 0.01" priority="1" '
        'solref="0.02 1" friction="1.5 0.02 0.001"/></worldbody></mujoco>')
    params = derods.ContactParams(priority=priority, solref=(0.004, 1.0), friction=0.7)
    w = World(spec, dt=2e-3, contact=params, scene_checks=False)
    w.add_rod(derods.Rod(shapes.straight(0.2, 10, start=(-0.1, 0.0, 0.0139)), derods.Material(young=1e7, radius=0.004)))
    w.step(5)
    con = w.data.contact
    assert w.data.ncon > 0
    want = ((0.02, 1.0), 1.5) if priority == 0 else ((0.004, 1.0), 0.7)
    np.testing.assert_allclose(con.solref[: w.data.ncon], np.broadcast_to(want[0], (w.data.ncon, 2)))
    np.testing.assert_allclose(con.friction[: w.data.ncon, 0], want[1])


def test_self_reach_leaves_out_edges_nearer_than_pi_r_along_the_rod():
    """Edges g apart are at least g - 1 shortest edges apart along the rod; a tube touches
    itself first across pi r (a closed hairpin), so the reach is the largest g with
    (g - 1) l < pi r, at least MuJoCo's own 1 (neighbours)."""
    from derods.sim.exclusion import self_reach
    assert self_reach(0.005, np.full(40, 0.01)) == 2      # the pile's cables: pi/2 l
    assert self_reach(0.001, np.full(40, 0.01)) == 1      # thin: neighbours only
    assert self_reach(0.01, np.full(40, 0.01)) == 4       # r = l: pi l
    assert self_reach(0.005, np.array([0.02, 0.01, 0.02])) == 2   # the shortest edge sets it


@pytest.mark.parametrize("mode", ["implicit", "alpha"])
def test_a_thick_rod_does_not_push_on_its_own_nearby_edges(mode):
    """A rod of r = l / 2 (the pile's cables) touches its edges two apart while straight
    (MuJoCo leaves out only neighbours), and each bend pushed them into each other: a
    stiffness the rod does not have. With those left out (self_reach), a cantilever
    sagging under gravity with self-collision on bends exactly as with it off, and no
    contact of the rod with itself is left in the rows. Measured with them kept: 34 and 9
    of them held the tip 0.20 m (implicit) and 6 mm (alpha) higher than its 0.36 m sag."""
    def tip(self_collision):
        x = shapes.straight(0.4, 40, start=(0.0, 0.0, 0.3))
        world = World(mujoco.MjSpec.from_string("<mujoco/>"), dt=2e-3, mode=mode, mass_damping=5.0,
                      contact=derods.ContactParams(self_collision=self_collision), scene_checks=False)
        world.add_rod(derods.Rod(x, derods.Material(young=2e6, radius=0.005)), "rod", start="clamp")
        world.step(400)
        d = world.data
        own = [c for c in d.contact[:d.ncon] if c.flex[0] >= 0 and c.flex[0] == c.flex[1] and not c.exclude]
        return world.positions("rod")[-1], len(own)

    free, _ = tip(False)
    touching, kept = tip(True)
    assert kept == 0
    assert free[2] < 0.3 - 0.05  # it sags
    np.testing.assert_allclose(touching, free, atol=1e-12)


def _jaws(jacobian: str, limit: float | None = None) -> World:
    """Two 0.2 kg jaws on slides (damping 5 N s/m), each its own tree, coupled by a joint
    equality (the second follows the first), the first servo-driven, squeezing a cable
    (r = 6 mm) lying on the floor; 1 s. limit: the second's range ends there [m] (its pad
    meets the cable near 12.3 mm)."""
    r = 0.006
    jaw = f'type="box" size="0.04 0.01 {r}" mass="0.2" friction="1"'
    stop = "" if limit is None else f' range="0 {limit}" limited="true"'
    xml = f"""<mujoco><option timestep="0.002" integrator="implicitfast" jacobian="{jacobian}"/><worldbody>
      <geom name="floor" type="plane" size="2 2 0.1"/>
      <body name="jl" pos="0 -0.03 {r}"><joint name="fl" type="slide" axis="0 1 0" damping="5"/><geom {jaw}/></body>
      <body name="jr" pos="0 0.03 {r}"><joint name="fr" type="slide" axis="0 -1 0" damping="5"{stop}/><geom {jaw}/>
      </body>
    </worldbody><equality><joint joint1="fr" joint2="fl"/></equality>
    <actuator><position joint="fl" kp="2000" ctrlrange="0 0.03"/></actuator></mujoco>"""
    world = World(mujoco.MjSpec.from_string(xml), dt=2e-3, contact=derods.ContactParams(friction=1.0),
                  scene_checks=False)
    x = shapes.straight(0.4, 30)
    x = np.stack([x[:, 0] - 0.2, np.zeros(len(x)), np.full(len(x), r + 1e-4)], axis=1)
    world.add_rod(derods.Rod(x, derods.Material(young=2e7, radius=r, density=1100.0)), "cable")
    world.compile()
    world.data.ctrl[0] = 0.03
    world.step(500)
    return world


@pytest.mark.parametrize("jacobian", ["sparse", "dense"])
def test_an_equality_between_joined_trees_is_solved_with_the_rods(jacobian):
    """The jaws' trees join the contact solve where they squeeze the cable, and so does the
    equality between them: its force is the one of derods' problem at the acceleration
    derods applied, -D (J qacc - aref) with D = 1 / ((R / diagA) J H^-1 J^T), H = M - h D
    on the jaws (to 1e-12 relative). Left with MuJoCo's force (until 2026-12-05, computed
    while MuJoCo saw the cable's bare vertex masses), it was 12 % off that (14.06 N where
    15.98 N balanced derods' step), and the jaws sat 3.07 mm from equal instead of 2.71
    (MuJoCo's soft equality under that load)."""
    world = _jaws(jacobian)
    m, d = world.model, world.data
    assert world.solved_bodies() == ["jl", "jr"]
    eq = int(np.flatnonzero(d.efc_type[:d.nefc] == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY))[0])
    jac = np.zeros((d.nefc, m.nv))
    if jacobian == "sparse":
        mujoco.mju_sparse2dense(jac, d.efc_J, d.efc_J_rownnz, d.efc_J_rowadr, d.efc_J_colind)
    else:
        jac[:] = d.efc_J.reshape(d.nefc, m.nv)
    row = jac[eq]
    metric = 0.2 + m.opt.timestep * 5.0  # each jaw's M - h D
    weight = 1.0 / (d.efc_R[eq] / d.efc_diagA[eq] * (row[:2] ** 2).sum() / metric)
    assert d.efc_force[eq] == pytest.approx(-weight * (row @ d.qacc - d.efc_aref[eq]), rel=1e-12)
    fl, fr = d.qpos[m.joint("fl").qposadr[0]], d.qpos[m.joint("fr").qposadr[0]]
    assert abs(fl - fr) < 2.8e-3


def test_a_joint_limit_of_a_joined_tree_is_solved_with_the_rods():
    """The same jaws, the second's slide ending 0.5 mm past where its pad meets the cable:
    its limit row holds it there with the force of derods' problem at the acceleration
    derods applied, D max(aref - J qacc, 0) (to 1e-12 relative), as the equality's is."""
    world = _jaws("sparse", limit=0.0128)
    m, d = world.model, world.data
    assert world.solved_bodies() == ["jl", "jr"]
    rows = np.flatnonzero(d.efc_type[:d.nefc] == int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT))
    assert len(rows) == 1
    lim = int(rows[0])
    jac = np.zeros((d.nefc, m.nv))
    mujoco.mju_sparse2dense(jac, d.efc_J, d.efc_J_rownnz, d.efc_J_rowadr, d.efc_J_colind)
    row = jac[lim]
    metric = 0.2 + m.opt.timestep * 5.0
    weight = 1.0 / (d.efc_R[lim] / d.efc_diagA[lim] * (row[:2] ** 2).sum() / metric)
    expected = weight * max(d.efc_aref[lim] - row @ d.qacc, 0.0)
    assert expected > 1.0  # the limit carries the squeeze
    assert d.efc_force[lim] == pytest.approx(expected, rel=1e-12)


def test_cg_forcing_term_follows_eisenstat_walker_within_its_bounds():
    """CG's tolerance in Newton's iterative solve (derods/_numba/contact_cg.py, forcing): the
    first solve CG_TOL_MAX; then CG_FORCING (|g_k| / |g_k-1|)^2, kept in [CG_TOL_MIN,
    CG_TOL_MAX] and, while the last one squared is large, no lower than that."""
    from derods._numba import contact_cg as cg
    assert cg.forcing(0.5, 1.0, 0.0) == cg.CG_TOL_MAX  # the first solve
    assert cg.forcing(cg.CG_TOL_MAX, 1.0, 1.0) == cg.CG_TOL_MAX  # no progress: loose
    assert cg.forcing(cg.CG_TOL_MAX, 1e-6, 1.0) == cg.CG_TOL_MIN  # fast progress: the floor
    eta = cg.forcing(0.05, 0.2, 1.0)  # in between: the formula
    assert eta == pytest.approx(cg.CG_FORCING * 0.04)
    assert cg.CG_TOL_MIN < eta < cg.CG_TOL_MAX
    big = cg.forcing(0.4, 1e-3, 1.0)  # the safeguard: eta_k-1 = 0.4 is large, 0.9 * 0.16 wins
    assert big == pytest.approx(min(cg.CG_TOL_MAX, cg.CG_FORCING * 0.16))


def test_fused_gram_product_equals_the_two_passes_to_the_bit():
    """J^T W J v in one pass over the rows (contact_cg.gram_apply_into) against J v, times
    W, then J^T of it (contact_rows.apply_all, transpose_apply_all): the same sums in the
    same order, inactive rows (w = 0) skipped."""
    from derods._numba.contact_cg import gram_apply_into
    from derods._numba.contact_rows import Rows, apply_all, transpose_apply_all
    rng = np.random.default_rng(3)
    n, kb, kf = 60, 25, 40
    col0 = rng.integers(0, n - 3, size=kb)  # windows that run past the end too
    jw = rng.normal(size=(kb, 9))
    cols = [np.sort(rng.choice(n, 12, replace=False)) for _ in range(kf)]
    fptr = np.concatenate([[0], np.cumsum([len(c) for c in cols])]).astype(np.int64)
    rows = Rows(col0.astype(np.int64), jw, fptr, np.concatenate(cols).astype(np.int64), rng.normal(size=fptr[-1]))
    w = rng.uniform(1, 10, size=kb + kf) * (rng.random(kb + kf) < 0.6)
    v = rng.normal(size=n)
    out = np.full(n, np.nan)
    gram_apply_into(rows, w, v, out)
    want = transpose_apply_all(rows, apply_all(rows, v) * w, n)
    assert np.array_equal(out, want)
