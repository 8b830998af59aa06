"""Hair (derods/hair.py): roots on the scalp, curled rest shapes, strands riding on a
moving head without stretching or sinking into it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from derods import hair


def test_scalp_sites_cover_the_scalp_evenly():
    """Unit vectors, all inside the hairline, none closer than a third of the mean spacing."""
    n = 400
    s = hair.scalp_sites(n, seed=3)
    assert s.shape == (n, 3)
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, rtol=1e-12)
    polar = np.arccos(np.clip(s[:, 2], -1, 1))
    azimuth = np.arctan2(s[:, 1], s[:, 0])
    assert np.all(polar <= hair.hairline(azimuth) + 1e-12)
    d = np.linalg.norm(s[:, None] - s[None], axis=-1) + 10 * np.eye(n)
    area = 2 * math.pi * (1 - np.cos(hair.hairline(azimuth))).mean()  # scalp share, roughly
    assert d.min() > math.sqrt(area / n) / 3
    np.testing.assert_array_equal(s, hair.scalp_sites(n, seed=3))


@pytest.mark.parametrize("curl", [0.0, 0.008])
def test_strand_shape_is_a_helix_of_exact_segments(curl):
    """Edges all ``segment`` long (to round-off), the first along the normal, the rest on a
    cylinder of the curl radius about the normal through the first edge's end."""
    root, normal = np.array([0.1, 0.2, 1.6]), np.array([0.0, 0.6, 0.8])
    x = hair.strand_shape(root, normal, 32, 0.01, curl, 0.05, phase=0.7, hand=-1)
    assert x.shape == (32, 3)
    np.testing.assert_allclose(np.linalg.norm(np.diff(x, axis=0), axis=1), 0.01, rtol=1e-12)
    np.testing.assert_allclose(x[1] - x[0], 0.01 * normal, atol=1e-15)
    rel = x[1:] - x[1]
    axial = rel @ normal
    radial = np.linalg.norm(rel - axial[:, None] * normal, axis=1)
    if curl == 0:
        np.testing.assert_allclose(radial, 0.0, atol=1e-15)
    else:
        assert radial.max() == pytest.approx(2 * curl, rel=0.02)  # the far side of the cylinder
    assert np.all(np.diff(axial) > 0)  # it rises along the normal all the way


def test_hair_input_errors():
    with pytest.raises(ValueError, match="strands must be an integer >= 1"):
        hair.Hair(strands=0)
    with pytest.raises(ValueError, match="curl_radius must be a range"):
        hair.Hair(curl_radius=(0.01, 0.001))
    with pytest.raises(ValueError, match="motion must be one of"):
        hair.Motion("spin")


@pytest.fixture(scope="module")
def shaken():
    """40 strands x 32 vertices on a head shaken for 1.5 s at dt = 1e-2 s, with the measures
    taken every step after the hair settled (0.3 s)."""
    h = hair.Hair(strands=40)
    w = hair.build(h)
    drive = hair.drive(w, hair.Motion("shake"))
    rec = {"pen": [], "drift": [], "strain": []}
    while w.time < 1.5 - 1e-9:
        drive(w)
        w.step()
        rec["pen"].append(hair.penetration(w))
        rec["drift"].append(hair.root_drift(w, h))
        rec["strain"].append(hair.max_strain(w))
    return h, w, {k: np.array(v) for k, v in rec.items()}


def test_hair_rides_on_the_shaken_head(shaken):
    """Roots stay on their scalp sites (clamped to the head: round-off), strands stay
    inextensible to the hair strain limit (1e-4, the projection's), the head moved."""
    h, w, rec = shaken
    assert rec["drift"].max() < 1e-9
    assert rec["strain"].max() <= hair.STRAIN_LIMIT * (1 + 1e-6)
    assert len(w.rods) == 40 and w.rods[0].n_vertices == 32
    quat = w.data.mocap_quat[0]
    assert abs(quat[0]) < 0.999  # turned


def test_hair_does_not_sink_into_the_head(shaken):
    """Strands touch the skull (there are contacts) and, past the first second's impacts,
    stay out of it to well below their radius (measured with 300 strands: 0.15 mm at worst
    with the default 5 mm margin)."""
    h, w, rec = shaken
    late = rec["pen"][100:]
    assert w.data.ncon > 0
    assert late.max() < 0.5 * h.radius  # measured 0.03 mm here; 1.3 mm with margin=0


@pytest.mark.parametrize("backend", ["der", "flex"])
def test_bench_hair_records_what_the_issue_asks(backend):
    """``derods bench hair``'s record: build time, step cost, stability, penetration after
    impacts, strain and root drift, for derods and for the native flexcomps."""
    from derods.bench import hair as hair_bench

    rec = hair_bench.run(hair_bench.HairCase(strands=6, vertices=12, seconds=0.6, backend=backend))
    for key in ("build_s", "us_per_step", "median_us_per_step", "stable", "penetration", "penetration_max",
                "max_strain", "root_drift", "strands", "vertices", "dt", "motion"):
        assert key in rec, key
    assert rec["stable"] and rec["steps"] == 60 and rec["build_s"] > 0
    assert rec["root_drift"] < 1e-6  # both ride on the head
    if backend == "der":
        assert rec["max_strain"] <= hair.STRAIN_LIMIT * (1 + 1e-6)
    line = hair_bench.format_record(rec)
    assert f"hair {backend}: 6 strands x 12 vertices" in line


def test_bench_hair_refuses_bad_input():
    from derods.bench import hair as hair_bench

    with pytest.raises(ValueError, match="backend must be one of"):
        hair_bench.HairCase(backend="cable")
    with pytest.raises(ValueError, match="dt must be finite and > 0"):
        hair_bench.HairCase(dt=0.0)
    with pytest.raises(ValueError, match="strand_contact is derods' option"):
        hair_bench.HairCase(backend="flex", strand_contact=True)


def test_derods_hair_writes_a_video_and_a_still(tmp_path, capsys):
    """The command with small settings: exit 0, the video and the PNG, a summary line
    with the build time, penetration and strain; strands are drawn as lines."""
    from derods.__main__ import main
    from derods.viz import output

    out, still = tmp_path / "h.mp4", tmp_path / "h.png"
    assert main(["hair", "--strands", "40", "--vertices", "16", "--seconds", "0.4", "--fps", "10", "--width", "320",
                 "--height", "180", "--out", str(out), "--still", str(still), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "40 strands x 16 vertices built in" in text and "deepest strand in the skull" in text
    assert out.stat().st_size > 1000
    img = output.mediapy().read_image(still)
    assert img.shape == (180, 320, 3)
    # Hair-coloured pixels (red > green > blue, darkish): the strands are drawn.
    r, g, b = (img[..., k].astype(int) for k in range(3))
    assert np.count_nonzero((r > g + 20) & (g > b + 10) & (r < 200)) > 50


def test_derods_hair_refuses_bad_input(tmp_path, capsys):
    from derods.__main__ import main

    assert main(["hair", "--strands", "0", "--out", str(tmp_path / "h.mp4"), "--quiet"]) == 2
    assert "strands must be an integer >= 1" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_report_has_a_hair_section(tmp_path):
    """Hair records in a results file (as benchmarks/bench_hair.py --append-to writes them)
    become the report's hair table, an unstable one with its note."""
    import json

    from derods.bench import hair as hair_bench
    from derods.bench import report

    rec = hair_bench.run(hair_bench.HairCase(strands=4, vertices=8, seconds=0.1))
    bad = dict(rec, backend="flex", stable=False, note="diverged at step 3")
    results = tmp_path / "r.jsonl"
    results.write_text(json.dumps(rec) + "\n" + json.dumps(bad) + "\n")
    text = report.report(results, tmp_path / "report").read_text()
    assert "## hair" in text
    assert "| der | 4 |" in text and "| flex | 4 |" in text and "UNSTABLE" in text and "diverged at step 3" in text
