"""Compiled (numba) kernels, split by concern: one rod step (:mod:`.step`), banded
linear algebra (:mod:`.banded`), the contact rows (:mod:`.row_split`, :mod:`.contact_rows`)
and so on. Each mirrors a numpy path that the tests hold it to.

numba caches a kernel's machine code keyed on its own file's stamp, not on the files of
the kernels it calls nor of the constants it reads: after a change to ``contact_cg.py``
alone, ``contact.py``'s cached kernels would keep running the old conjugate gradients
(a checkout updated by ``git pull``, an edited kernel). So on import the caches of these
kernels are dropped whenever any of their sources differs from the sources they were
compiled from (:func:`drop_stale_caches`); an installed wheel, whose files change all at
once, never meets the case.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

#: The file beside the kernels' caches that names the sources they were compiled from.
STAMP = "derods-kernel-sources.sha256"


def kernel_sources(directory: Path) -> list[Path]:
    """The kernels' sources: every module of ``directory`` (this package) and the modules of
    the parent package they take constants from (``from ..geometry import ...``)."""
    own = sorted(directory.glob("*.py"))
    parents = set()
    for path in own:
        parents.update(re.findall(r"^from \.\.(\w+) import", path.read_text(), flags=re.MULTILINE))
    return own + [directory.parent / f"{name}.py" for name in sorted(parents)]


def fingerprint(paths: list[Path]) -> str:
    """A hash of the files' names and contents."""
    h = hashlib.sha256()
    for path in paths:
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def drop_stale_caches(sources: list[Path], cache_dir: Path) -> bool:
    """Remove numba's cache files (``*.nbi``, ``*.nbc``) from cache_dir unless its stamp
    names these sources' fingerprint, then stamp it (written whole, by a rename). Returns
    whether caches were dropped. A cache directory that cannot be written is left alone
    (numba cannot have written stale caches there either)."""
    now = fingerprint(sources)
    stamp = cache_dir / STAMP
    try:
        if stamp.read_text() == now:
            return False
    except OSError:
        pass
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        dropped = False
        for path in cache_dir.iterdir():
            if path.suffix in (".nbi", ".nbc"):
                path.unlink(missing_ok=True)  # another process may drop it first
                dropped = True
        part = cache_dir / f"{STAMP}.{os.getpid()}.tmp"
        part.write_text(now)
        os.replace(part, stamp)
    except OSError:
        return False
    return dropped


def _cache_dir() -> Path:
    """Where numba caches these kernels: beside the sources (``__pycache__``) unless
    NUMBA_CACHE_DIR moves it, asked of one kernel's cache."""
    from .banded import cholesky_into

    try:
        return Path(cholesky_into._cache._cache_path)
    except AttributeError:  # a numba that keeps it elsewhere: the default place
        return Path(__file__).parent / "__pycache__"


drop_stale_caches(kernel_sources(Path(__file__).parent), _cache_dir())
