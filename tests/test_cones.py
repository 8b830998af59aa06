"""Elliptic friction cones in derods' contact solve (derods/_numba/cones.py): the cone's
force law is MuJoCo's own, Newton's method with cones finds the minimum of the same
objective a general-purpose minimizer finds, and a world of elliptic contacts has derods
solve them (before 2026-12-05 their rows kept MuJoCo's force)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import scipy.optimize
from oracles import ContactRows, a_matvec, implicit_system, random_band

import derods
from derods import ContactParams, World, shapes
from derods._numba import contact_newton as _newton
from derods._numba.cones import Cones, cone_forces
from derods.sim.contact import MAX_ITER, TOL

_BOX = """<mujoco><option cone="elliptic" impratio="{imp}" tolerance="1e-14" iterations="200"/><worldbody>
<geom type="plane" size="1 1 .1" friction="0.3 0.01 0.001"/>
<body pos="0 0 0.099"><freejoint/><geom type="box" size=".1 .1 .1" condim="{dim}" friction="0.3 0.02 0.001"/></body>
</worldbody></mujoco>"""


@pytest.mark.parametrize("imp,dim,vel", [(1, 3, 0.3), (3, 3, 0.3), (1, 4, 0.3), (1, 6, 0.3), (1, 3, 0.0)])
def test_the_cones_forces_are_mujocos(imp, dim, vel):
    """A box sliding (or resting: vel = 0) on a plane, MuJoCo's own elliptic solve to 1e-14:
    derods' cone forces at MuJoCo's solution (jar = J qacc - aref per row) equal MuJoCo's
    efc_force to 1e-10 relative (round-off of the solve), with impratio 1 and 3, condim 3,
    4 and 6 (torsional and rolling friction in the cone), in the middle zone (sliding) and
    the bottom zone (resting)."""
    m = mujoco.MjModel.from_xml_string(_BOX.format(imp=imp, dim=dim))
    d = mujoco.MjData(m)
    d.qvel[0], d.qvel[5] = vel, 0.5 * vel
    mujoco.mj_forward(m, d)
    jac = d.efc_J.reshape(d.nefc, m.nv)
    jar = jac @ d.qacc - d.efc_aref
    con = d.contact
    rows = np.full((d.ncon, 6), -1, dtype=np.int64)
    for c in range(d.ncon):
        rows[c, :dim] = con.efc_address[c] + np.arange(dim)
    cones = Cones(rows, np.full(d.ncon, dim, dtype=np.int64), np.ascontiguousarray(con.mu),
                  np.ascontiguousarray(con.friction))
    lam = np.zeros(d.nefc)
    cone_forces(cones, jar, np.ascontiguousarray(d.efc_D), lam)
    np.testing.assert_allclose(lam, d.efc_force, rtol=0, atol=1e-10 * np.abs(d.efc_force).max())


def _cone_cost(jar, d, rows, dim, mu, friction):
    """MuJoCo's elliptic cone cost of one contact at its rows' jar (the module docstring of
    derods/_numba/cones.py; its force law is checked against MuJoCo above)."""
    r = rows[:dim]
    u = np.concatenate([[mu * jar[r[0]]], friction[:dim - 1] * jar[r[1:]]])
    n_, t_ = u[0], np.linalg.norm(u[1:])
    if n_ >= mu * t_:
        return 0.0
    if mu * n_ + t_ <= 0:
        return 0.5 * np.sum(d[r] * jar[r] ** 2)
    return 0.5 * d[r[0]] / (mu * mu * (1 + mu * mu)) * (n_ - mu * t_) ** 2


@pytest.mark.parametrize("far", [False, True])
def test_newton_with_cones_finds_the_minimum(far):
    """Random problem over 6 vertices: 5 scalar rows and 4 cones (dims 3, 3, 4, 6; banded, or
    between the first and the last vertex: far rows, their patterns shared), aref spread
    so that cones land in each zone. Newton's answer equals BFGS's on the same objective
    (rtol 1e-5: BFGS's own stopping), its optimality condition A (a - a0) = J^T lam holds to
    1e-9 of the force scale (Newton stops at 1e-10 of it), the cones' forces lie in their
    cones, and each zone occurs."""
    rng = np.random.default_rng(3)
    n = 18
    system = implicit_system(1e-2, np.array([0, n]), [random_band(rng, n)], [(rng.normal(size=n), 2.0)],
                             rng.uniform(0.5, 1.5, size=n), 0.3, 1e-3)
    dims = [3, 3, 4, 6]
    n_scalar = 5
    k_cone = sum(dims)
    col0 = list(rng.integers(0, n - 6, size=n_scalar))
    jw = [np.concatenate([rng.normal(size=6), np.zeros(3)]) for _ in range(n_scalar)]
    jf = []
    rows = np.full((len(dims), 6), -1, dtype=np.int64)
    at = n_scalar
    for c, dim in enumerate(dims):
        if far:
            for j in range(dim):
                row = np.zeros(n)
                row[:3], row[-3:] = rng.normal(size=3), rng.normal(size=3)
                jf.append(row)
            rows[c, :dim] = n_scalar + len(jf) - dim + np.arange(dim)
        else:
            start = rng.integers(0, n - 6)
            for j in range(dim):
                col0.append(start)
                jw.append(np.concatenate([rng.normal(size=6), np.zeros(3)]))
            rows[c, :dim] = at + np.arange(dim)
            at += dim
    k = n_scalar + k_cone
    mu = np.array([2.0, 0.8, 0.5, 0.2])  # the first cone wide: it sticks
    friction = np.array([[2.0, 2.0, 0, 0, 0], [0.8, 0.8, 0, 0, 0], [0.5, 0.5, 0.05, 0, 0],
                         [0.2, 0.2, 0.03, 0.01, 0.01]])
    d = rng.uniform(1, 50, size=k)
    cones = Cones(rows, np.array(dims, dtype=np.int64), mu, friction)
    for c, dim in enumerate(dims):  # MuJoCo's coupling of a cone's weights
        d[rows[c, 1:dim]] = d[rows[c, 0]] * friction[c, :dim - 1] ** 2 / mu[c] ** 2
    aref = rng.normal(size=k) * 5
    aref[rows[:, 0]] = [20.0, 3.0, -60.0, 12.0]  # normal rows pushing in, one pulling out
    contact_rows = ContactRows(np.array(col0, dtype=np.int64), np.array(jw), aref, d, np.arange(k),
                               jf=np.array(jf) if jf else None)
    a0 = rng.normal(size=n)
    a, _, lam, iters = _newton.newton(system.arrays, a0, contact_rows.rows(n), aref, d,
                                      _newton.no_border(n, k), cones, MAX_ITER, TOL)
    in_cone = np.zeros(k, dtype=bool)
    in_cone[rows[rows >= 0]] = True

    def f(x):
        jar = contact_rows.apply(x) - aref
        r = np.minimum(jar[~in_cone], 0.0)
        cost = 0.5 * (x - a0) @ a_matvec(system, x - a0) + 0.5 * np.sum(d[~in_cone] * r * r)
        return cost + sum(_cone_cost(jar, d, rows[c], dims[c], mu[c], friction[c]) for c in range(len(dims)))

    ref = scipy.optimize.minimize(f, a0, method="BFGS", options={"gtol": 1e-12, "maxiter": 20000}).x
    np.testing.assert_allclose(a, ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max())
    grad = a_matvec(system, a - a0) - contact_rows.transpose_apply(lam, n)
    scale = np.abs(a_matvec(system, a0)).max() + np.abs(d * aref).max()  # Newton stops at TOL = 1e-10 of it
    np.testing.assert_allclose(grad, 0.0, atol=1e-9 * scale)
    zones = []
    for c, dim in enumerate(dims):
        f_ = lam[rows[c, :dim]]
        slide = np.linalg.norm(f_[1:] / friction[c, :dim - 1])
        assert f_[0] >= 0 and slide <= f_[0] * (1 + 1e-9)
        zones.append("top" if f_[0] == 0 else "middle" if slide >= f_[0] * (1 - 1e-9) else "bottom")
    assert {"top", "middle", "bottom"} <= set(zones), zones
    assert iters < MAX_ITER


def test_an_elliptic_world_has_derods_solve_its_contacts():
    """A cable lying on a floor with elliptic cones: the contact stage solves its rows (the
    force it applied to the rod is what MuJoCo's readers see: World.contacts() against the
    rod's weight) and MuJoCo's own solver is skipped (every row is derods')."""
    spec = mujoco.MjSpec()
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    floor = spec.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [1.0, 1.0, 0.1]
    world = World(spec, dt=2e-3, contact=ContactParams(friction=0.5))
    material = derods.Material(young=1e7, radius=3e-3, density=1000.0)
    world.add_rod(derods.Rod(shapes.straight(0.3, 30, start=(0.0, 0.0, 2.9e-3)), material))
    world.step(300)
    weight = material.density * np.pi * material.radius ** 2 * 0.3 * 9.81
    normal = sum(c.normal_force for c in world.contacts())
    assert normal == pytest.approx(weight, rel=0.02)
    assert world._step.forward.skipped
    assert world.positions()[:, 2].min() > 0.5 * material.radius


@pytest.mark.parametrize("cone", ["pyramidal", "elliptic"])
def test_a_cable_on_a_moving_mocap_platform_rides_it(cone):
    """A cable lying on a mocap body's box that slides at 0.1 m/s: MuJoCo's rows cannot see
    a body without dofs move, so derods adds its velocity to them
    (derods/_numba/contact_reference.py); with either cone the cable rides along, its
    centre's speed within 1 % of the platform's over the last 0.2 s of 0.6 s (without the
    elliptic rows' correction it stayed behind: friction damped it to the world's rest)."""
    spec = mujoco.MjSpec()
    spec.option.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[cone]
    body = spec.worldbody.add_body()
    body.mocap = True
    plate = body.add_geom()
    plate.type = mujoco.mjtGeom.mjGEOM_BOX
    plate.size = [1.0, 0.2, 0.01]
    plate.pos = [0.0, 0.0, -0.01]
    world = World(spec, dt=2e-3, contact=ContactParams(friction=0.8))
    material = derods.Material(young=1e7, radius=3e-3, density=1000.0)
    world.add_rod(derods.Rod(shapes.straight(0.3, 30, start=(-0.15, 0.0, 2.9e-3)), material))
    world.step(50)
    speed, steps = 0.1, 300
    for k in range(steps):
        world.data.mocap_pos[0, 0] = speed * (k + 1) * 2e-3
        if k == steps - 100:
            before = world.positions().mean(axis=0)
        world.step()
    ridden = (world.positions().mean(axis=0)[0] - before[0]) / (100 * 2e-3)
    assert ridden == pytest.approx(speed, rel=0.01)
