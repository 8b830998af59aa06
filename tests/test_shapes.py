"""Rest shapes of derods/shapes.py, Bezier curves above all (Bergou et al. 2008, fig. 4)."""

from __future__ import annotations

import numpy as np
import pytest

from derods import frames as fr
from derods import geometry as ge
from derods import shapes

# Two cubic segments; the inner control points 2 and 4 do NOT line up with the join 3.
CONTROL = np.array([
    [0.0, 0.0, 0.0], [0.3, 0.4, 0.0], [0.6, 0.5, 0.2], [1.0, 0.3, 0.2],
    [1.2, -0.3, 0.5], [1.5, 0.0, 0.0], [1.8, 0.4, 0.1],
])


def test_c1_join_has_continuous_tangent_and_c0_may_corner():
    for cont, corner in (("C1", False), ("C0", True)):
        p = shapes.bezier_control_points(CONTROL, cont)
        left = shapes.bezier_eval(p, 1.0 - 1e-15, derivative=1)
        right = shapes.bezier_eval(p, 1.0, derivative=1)
        ta, tb = left / np.linalg.norm(left), right / np.linalg.norm(right)
        if corner:
            assert np.linalg.norm(ta - tb) > 0.1
        else:
            np.testing.assert_allclose(ta, tb, atol=1e-9)
    # C1 leaves the given points alone except the mirrored one.
    p1 = shapes.bezier_control_points(CONTROL, "C1")
    np.testing.assert_array_equal(np.delete(p1, 4, axis=0), np.delete(CONTROL, 4, axis=0))
    np.testing.assert_allclose(p1[4], 2 * CONTROL[3] - CONTROL[2])


def join_edge(x, p):
    """Index of the edge of the resampled rod that contains the join of the segments."""
    d = np.linalg.norm(x - shapes.bezier_eval(p, 1.0), axis=1)
    return int(np.argmin(d))


def frame_rotation(x, k0, k1):
    """Angle [rad] of the rotation taking the Bishop frame of edge k0 to that of edge k1."""
    t = fr.tangents(x, False)
    u = fr.bishop_frames(x, False)
    f = np.stack([t, u, np.cross(t, u)], axis=-1)
    r = f[k1] @ f[k0].T
    return float(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))


@pytest.mark.parametrize("n", [60, 240, 960])
def test_bishop_frames_continuous_across_c1_join(n):
    """Over the four edges around a join the Bishop frame turns by O(h) across a C1
    join (it vanishes as the rod is refined: measured 0.113, 0.028, 0.0070 rad at
    n = 60, 240, 960, i.e. 6.8 / n; bound 8 / n), but by the corner angle (0.878 rad)
    across a C0 join however fine the rod (measured within 5.4 / n of it; bound 8 / n)."""
    for cont in ("C0", "C1"):
        p = shapes.bezier_control_points(CONTROL, cont)
        x = shapes.bezier(CONTROL, n, cont)
        k = join_edge(x, p)
        rot = frame_rotation(x, k - 2, k + 2)
        left = shapes.bezier_eval(p, 1.0 - 1e-15, derivative=1)
        right = shapes.bezier_eval(p, 1.0, derivative=1)
        corner = np.arccos(left @ right / np.linalg.norm(left) / np.linalg.norm(right))
        if cont == "C1":
            assert corner < 1e-9
            assert rot < 8.0 / n
        else:
            assert corner > 0.5
            assert abs(rot - corner) < 8.0 / n


@pytest.mark.parametrize("cont", ["C0", "C1"])
def test_bezier_resampled_to_equal_arc_length(cont):
    x = shapes.bezier(CONTROL, 100, cont)
    assert x.shape == (101, 3)
    np.testing.assert_allclose(x[0], CONTROL[0], atol=1e-12)
    np.testing.assert_allclose(x[-1], CONTROL[-1], atol=1e-12)
    le = np.sort(ge.norm(ge.edges(x, False)))
    # Equal arc length; chords then differ by O((h kappa)^2): measured 4e-4 (C1) and
    # 1e-3 (C0) relative spread; bound 2e-3. The one edge across a C0 corner is a
    # shorter chord of its arc (0.937 of the mean here).
    if cont == "C0":
        assert 0.9 < le[0] / le.mean() < 0.95
        le = le[1:]
    assert np.ptp(le) / le.mean() < 2e-3


def test_bezier_degenerate_inputs_raise():
    bad = CONTROL.copy()
    bad[3:7] = bad[3]
    with pytest.raises(ValueError, match="segment 1 is degenerate"):
        shapes.bezier(bad, 20)
    bad = CONTROL.copy()
    bad[2] = bad[3]
    with pytest.raises(ValueError, match="C1 join 1"):
        shapes.bezier(bad, 20, "C1")
    shapes.bezier(bad, 20, "C0")  # a cusp-free C0 join with a zero handle is fine
    with pytest.raises(ValueError, match=r"shape \(3k\+1, 3\)"):
        shapes.bezier(CONTROL[:5], 20)
    with pytest.raises(ValueError, match="continuity"):
        shapes.bezier(CONTROL, 20, "G1")
    nan = CONTROL.copy()
    nan[1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        shapes.bezier(nan, 20)


def test_circle_and_helix_have_equal_edges_and_right_shape():
    x = shapes.circle(0.3, 40, center=(1, 2, 3), normal=(0, 1, 1))
    np.testing.assert_allclose(np.linalg.norm(x - [1, 2, 3], axis=1), 0.3, rtol=1e-14)
    np.testing.assert_allclose(x @ np.array([0, 1, 1]) / np.sqrt(2), 5 / np.sqrt(2), rtol=1e-14)
    le = ge.norm(ge.edges(x, True))
    np.testing.assert_allclose(le, le[0], rtol=1e-12)
    h = shapes.helix(0.1, 0.05, 3, 90)
    le = ge.norm(ge.edges(h, False))
    np.testing.assert_allclose(le, le[0], rtol=1e-12)
    np.testing.assert_allclose(h[-1, 2] - h[0, 2], 0.15, rtol=1e-12)


def test_resample_polyline():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0]], dtype=float)
    x = shapes.resample(pts, 6)
    # Arc length 3 in 6 edges of 0.5: the corner (arc length 1) lands on vertex 2.
    np.testing.assert_allclose(x[2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(ge.norm(ge.edges(x, False)), 0.5, rtol=1e-12)
    with pytest.raises(ValueError, match="n_edges"):
        shapes.resample(pts, 1)


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: shapes.straight(-1.0, 10), "length must be finite and > 0"),
        (lambda: shapes.straight(1.0, 1), "n_edges must be an integer >= 2"),
        (lambda: shapes.circle(0.1, 2), "n_edges must be an integer >= 3"),
        (lambda: shapes.circle(0.0, 10), "radius"),
        (lambda: shapes.helix(0.1, np.inf, 1, 10), "pitch"),
        (lambda: shapes.straight(1.0, 10, direction=(0, 0, 0)), "direction"),
    ],
)
def test_shape_errors_name_the_parameter(call, match):
    with pytest.raises(ValueError, match=match):
        call()
