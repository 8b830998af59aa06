"""The README and the documentation pages stay true to the tree: the README short with its
two commands, its links resolving; the module map naming every module of derods/ (and no
module that is gone); the API reference documenting every public name.

The site itself (the pages, the API reference from the docstrings, their links and
cross-references) is built strictly by ``make docs``, which CI runs: a broken reference
fails there."""

from __future__ import annotations

import pathlib
import re

import derods

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"


def _slug(heading: str) -> str:
    """A heading's anchor as the site's table of contents makes it (Python-Markdown's toc)."""
    text = re.sub(r"[^\w\s-]", "", heading.replace("`", "")).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def _anchors(page: pathlib.Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # no headings in code
    return {_slug(m) for m in re.findall(r"^#+ (.*)$", text, re.M)}


def test_readme_is_short_and_keeps_its_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 250, "the README is the entry page: move detail to docs/"
    assert "make demo   # the main job: drop rods onto a rigid scene, write out/drop.mp4 (headless)" in text
    assert "make test   # the test suite (pytest)" in text
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^demo: .*\n(\t.*\n)*\t.* -m derods drop --out out/drop.mp4$", makefile, re.M)
    assert re.search(r"^test: .*\n\t.* -m pytest -q$", makefile, re.M)


def test_readme_links_resolve():
    """Every relative link and picture of the README names a file of the repository, and a
    link into a page names one of its headings."""
    links = re.findall(r"\]\(([^)\s]+)\)", README.read_text())
    local = [link for link in links if not re.match(r"[a-z]+://", link)]
    assert any(link.startswith("docs/api/") for link in local), "the README links the API reference"
    for link in local:
        path, _, anchor = link.partition("#")
        target = ROOT / path
        assert target.exists(), f"README links {link!r}: no such file"
        if anchor:
            assert anchor in _anchors(target), f"README links {link!r}: {path} has no heading with that anchor"


def test_module_map_names_every_module():
    """docs/modules.md has a line for each module of derods/ (a package by its
    ``__init__.py``), and names no module that is not there."""
    text = (DOCS / "modules.md").read_text()
    named = set(re.findall(r"`(derods/[\w/]+\.py)`", text))
    present = {p.relative_to(ROOT).as_posix() for p in (ROOT / "derods").rglob("*.py")}
    assert not present - named, f"add a line to docs/modules.md for {sorted(present - named)}"
    assert not named - present, f"docs/modules.md names modules that are gone: {sorted(named - present)}"


def test_api_reference_documents_every_public_name():
    """Each name ``import derods`` exports is rendered by a ``::: derods.NAME`` of
    docs/api/ (where the site's build resolves it, or fails)."""
    text = "\n".join(p.read_text() for p in (DOCS / "api").glob("*.md"))
    rendered = set(re.findall(r"^::: derods\.(\w+)$", text, re.M))
    public = set(derods.__all__) - {"__version__"}
    assert not public - rendered, f"add '::: derods.NAME' to docs/api/ for {sorted(public - rendered)}"
