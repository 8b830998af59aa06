"""The README's tour and the guide's Python examples run as written (from the repository
root)."""

from __future__ import annotations

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).parents[1]


@pytest.mark.parametrize("page", ["README.md", "docs/guide.md"])
def test_python_examples_run(monkeypatch, page):
    text = (ROOT / page).read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 2, f"{page} lost its Python examples"
    monkeypatch.chdir(ROOT)
    core: dict = {}
    exec(compile(blocks[0], page, "exec"), core)
    assert core["rod"].active_terms == ("stretch", "bend_isotropic", "twist")
    assert core["step"].hessian_banded.shape == (9, 3 * 41)
    scene: dict = {}
    exec(compile(blocks[1], page, "exec"), scene)
    assert scene["x"].shape == (41, 3) and scene["world"].mode == "implicit"
    # The dropped rod has landed on the box or the floor and carries its weight there.
    assert scene["x"][:, 2].min() < 0.25
