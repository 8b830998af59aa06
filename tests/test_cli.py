"""The command line of derods/__main__.py."""

from __future__ import annotations

from derods.__main__ import main


def test_demo_runs_and_reports_closed_forms(capsys):
    assert main(["demo", "--n-edges", "12"]) == 0
    out = capsys.readouterr().out
    assert "C1:" in out and "C0:" in out
    assert "critical twist 2 pi sqrt(3) alpha / beta" in out


def test_bad_input_is_one_line_error_and_nonzero_exit(capsys):
    assert main(["demo", "--young", "-3"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "derods demo: error: young must be finite and > 0 [Pa], got -3.0"


def test_view_without_a_display_says_so(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view"]) == 2
    err = capsys.readouterr().err
    assert "needs a display" in err and "derods drop" in err
