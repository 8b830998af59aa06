"""The README's Python example runs as written."""

from __future__ import annotations

import pathlib
import re


def test_readme_python_example_runs():
    readme = (pathlib.Path(__file__).parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    assert blocks, "the README lost its Python example"
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)
    assert namespace["rod"].active_terms == ("stretch", "bend_isotropic", "twist")
    assert namespace["step"].hessian_banded.shape == (9, 3 * 41)
