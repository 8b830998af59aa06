"""Parameters, state and active terms of derods/rod.py; input validation."""

from __future__ import annotations

import numpy as np
import pytest

import derods
from derods import shapes
from derods.twist import TwistBoundary

MAT = derods.Material(young=1e7, radius=0.01)


def test_active_terms_follow_the_configuration():
    """Only what the rod needs: no twist for a free isotropic straight rod, no material
    curvatures for an isotropic one, frames as soon as the rest shape is curved."""
    straight = shapes.straight(1.0, 10)
    assert derods.Rod(straight, MAT).active_terms == ("stretch", "bend_isotropic")
    clamped = derods.Rod(straight, MAT, boundary=TwistBoundary("clamped", 0.0, 1.0))
    assert clamped.active_terms == ("stretch", "bend_isotropic", "twist")
    helix = derods.Rod(shapes.helix(0.1, 0.05, 1, 20), MAT)
    assert helix.active_terms == ("stretch", "bend_material", "twist")
    ribbon = derods.Rod(straight, derods.Material(young=1e7, radius=0.01, radius2=0.002))
    assert ribbon.active_terms == ("stretch", "bend_material", "twist")
    with pytest.raises(ValueError, match="not active"):
        derods.Rod(straight, MAT).derivatives(derods.Rod(straight, MAT).rest_state(), 1, terms=("twist",))


@pytest.mark.parametrize("shape,closed,natural", [
    (lambda: shapes.helix(0.1, 0.05, 1.5, 30), False, True),
    (lambda: shapes.bezier([[0, 0, 0], [0.2, 0.3, 0], [0.5, 0.1, 0.2], [0.7, 0.4, 0.1]], 25), False, True),
    (lambda: shapes.circle(0.2, 30), True, True),
    (lambda: shapes.straight(1.0, 12), False, True),
])
@pytest.mark.parametrize("bending", ["tan", "angle"])
def test_rest_shape_is_stress_free(shape, closed, natural, bending):
    """Naturally curved rods rest in their own shape: zero energy and zero force, with either
    measure of bending (the rest curvatures are taken with the measure the energy uses; taken
    with the other, the helix would rest with 6e-5 J and forces of 0.06 N, measured)."""
    bd = TwistBoundary("ring") if closed else TwistBoundary()
    rod = derods.Rod(shape(), derods.Material(young=1e7, radius=0.01, radius2=0.006),
                     closed=closed, boundary=bd, bending=bending)
    state = rod.advance(rod.rest_state(), rod.rest_x)
    d = rod.derivatives(state, 1)
    assert abs(d.energy) < 1e-20
    np.testing.assert_allclose(d.grad_x, 0.0, atol=1e-12)


def test_vertex_masses_are_lumped():
    rod = derods.Rod(shapes.straight(2.0, 10), MAT)
    m = rod.vertex_mass
    np.testing.assert_allclose(m.sum(), MAT.line_density * 2.0, rtol=1e-14)
    np.testing.assert_allclose(m[0], m[1] / 2, rtol=1e-14)
    ring = derods.Rod(shapes.circle(0.3, 12), MAT, closed=True, boundary=TwistBoundary("ring"))
    np.testing.assert_allclose(ring.vertex_mass, ring.vertex_mass[0], rtol=1e-12)


def test_material_constants():
    """alpha = E pi r^4 / 4, beta = G pi r^4 / 2 with G = E / (2 (1 + nu))."""
    m = derods.Material(young=2e9, radius=0.002, poisson=0.3)
    np.testing.assert_allclose(m.alpha, 2e9 * np.pi * 0.002**4 / 4, rtol=1e-14)
    np.testing.assert_allclose(m.beta, 2e9 / 2.6 * np.pi * 0.002**4 / 2, rtol=1e-14)
    np.testing.assert_allclose(derods.Material(young=1.0, shear=3.0).shear_modulus, 3.0)


@pytest.mark.parametrize("kwargs,match", [
    ({"young": -3.0}, r"young must be finite and > 0 \[Pa\], got -3.0"),
    ({"young": 0.0}, "young"),
    ({"young": 1e6, "density": 0.0}, r"density must be finite and > 0 \[kg/m\^3\]"),
    ({"young": 1e6, "radius": -0.01}, r"radius must be finite and > 0 \[m\]"),
    ({"young": 1e6, "shear": -1.0}, r"shear must be finite and > 0 \[Pa\]"),
    ({"young": float("nan")}, "young"),
    ({"young": 1e6, "poisson": 0.7}, r"poisson must be in \(-1, 0.5\]"),
    ({"young": 1e30}, r"young = 1e\+30 Pa is stiffer than any material.*<= 1e\+13 Pa"),
    ({"young": 1e9, "shear": 1e14}, r"shear = 1e\+14 Pa is stiffer than any material"),
])
def test_material_errors_name_the_parameter(kwargs, match):
    with pytest.raises(ValueError, match=match):
        derods.Material(**kwargs)


def test_rod_input_errors():
    x = shapes.straight(1.0, 5)
    with pytest.raises(ValueError, match="at least 2 edges"):
        derods.Rod(x[:2], MAT)
    with pytest.raises(ValueError, match="closed rod needs at least 3 edges"):
        derods.Rod(x[:2], MAT, closed=True, boundary=TwistBoundary("ring"))
    dup = x.copy()
    dup[3] = dup[2]
    with pytest.raises(ValueError, match="edge 2 has zero length"):
        derods.Rod(dup, MAT)
    nan = x.copy()
    nan[1, 2] = np.inf
    with pytest.raises(ValueError, match=r"NaN or infinite coordinate at index \(1, 2\)"):
        derods.Rod(nan, MAT)
    with pytest.raises(ValueError, match="shape"):
        derods.Rod(x[:, :2], MAT)
    with pytest.raises(ValueError, match="stretch_stiffness"):
        derods.Rod(x, MAT, stretch_stiffness=0.0)


def test_bending_measure_is_checked():
    """``bending`` takes "tan" or "angle"; anything else is refused naming the parameter, the
    value and what to pass."""
    x = shapes.straight(1.0, 5)
    assert derods.Rod(x, MAT).bending == "tan"  # Bergou's measure unless asked otherwise
    assert derods.Rod(x, MAT, bending="angle").bending == "angle"
    with pytest.raises(derods.InvalidInputError, match=r"bending must be 'tan' \(Bergou's curvature binormal, the "
                       r"default\) or 'angle' \(the turning angle\), got 'curvature' \(str\): pass bending='angle'"):
        derods.Rod(x, MAT, bending="curvature")
    with pytest.raises(derods.InvalidTypeError, match="bending must be"):
        derods.Rod(x, MAT, bending=None)


@pytest.mark.parametrize("gap", [0.0, 1e-9, 0.005])
def test_a_rest_shape_folded_back_onto_itself_is_refused(gap):
    """Two edges folded back (a turn of 180 degrees, or within 1 degree of it) have an
    infinite discrete curvature: refused, naming the vertex. Exactly folded edges have
    kb = 0 / 0, so the check measures the angle with atan2, not kb."""
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, gap, 0.0]])
    with pytest.raises(ValueError, match=r"turns by 1(79|80)\.\d degrees at vertex 2"):
        derods.Rod(x, MAT)
    derods.Rod(np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.05, 0.0]]), MAT)  # 174 degrees
