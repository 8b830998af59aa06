"""The kernels' caches are dropped when any kernel source changes (derods/_numba/__init__.py):
numba keys a cached kernel on its own file only, so a caller's cache would keep a changed
callee's old code."""

from pathlib import Path

from derods import _numba


def make_sources(tmp_path: Path) -> tuple[Path, Path]:
    """A package ``pkg/kern`` of two kernel modules, one taking a constant from ``pkg/geo.py``;
    its cache directory with a cached kernel in it."""
    kern = tmp_path / "pkg" / "kern"
    kern.mkdir(parents=True)
    (tmp_path / "pkg" / "geo.py").write_text("LIMIT = 1.0\n")
    (tmp_path / "pkg" / "other.py").write_text("UNRELATED = 1\n")
    (kern / "a.py").write_text("def f():\n    return 1\n")
    (kern / "b.py").write_text("from ..geo import LIMIT\nfrom .a import f\n")
    cache = kern / "__pycache__"
    cache.mkdir()
    return kern, cache


def cached(cache: Path) -> list[str]:
    for name in ("b.g-1.py311.nbi", "b.g-1.py311.1.nbc"):
        if not (cache / name).exists():
            (cache / name).write_bytes(b"machine code")
    return sorted(p.name for p in cache.iterdir() if p.suffix in (".nbi", ".nbc"))


def test_kernel_sources_are_the_package_and_the_modules_it_takes_constants_from(tmp_path):
    kern, _ = make_sources(tmp_path)
    names = [p.relative_to(tmp_path).as_posix() for p in _numba.kernel_sources(kern)]
    assert names == ["pkg/kern/a.py", "pkg/kern/b.py", "pkg/geo.py"]


def test_caches_dropped_once_per_change_of_any_source(tmp_path):
    kern, cache = make_sources(tmp_path)
    sources = _numba.kernel_sources(kern)
    assert cached(cache)
    assert _numba.drop_stale_caches(sources, cache)  # no stamp yet: compiled from unknown sources
    assert not [p for p in cache.iterdir() if p.suffix in (".nbi", ".nbc")]
    kept = cached(cache)
    assert not _numba.drop_stale_caches(sources, cache)  # the same sources: kept
    assert [p.name for p in sorted(cache.iterdir()) if p.suffix in (".nbi", ".nbc")] == kept
    (tmp_path / "pkg" / "other.py").write_text("UNRELATED = 2\n")  # not a kernel source: kept
    assert not _numba.drop_stale_caches(_numba.kernel_sources(kern), cache)
    (tmp_path / "pkg" / "geo.py").write_text("LIMIT = 2.0\n")  # a constant a kernel reads
    assert _numba.drop_stale_caches(_numba.kernel_sources(kern), cache)
    assert not [p for p in cache.iterdir() if p.suffix in (".nbi", ".nbc")]
    cached(cache)
    (kern / "a.py").write_text("def f():\n    return 2\n")  # a callee's file alone
    assert _numba.drop_stale_caches(_numba.kernel_sources(kern), cache)


def test_this_package_is_stamped_with_its_own_sources():
    """Importing derods stamped the kernels' cache with the sources in this checkout."""
    here = Path(_numba.__file__).parent
    stamp = _numba._cache_dir() / _numba.STAMP
    assert stamp.read_text() == _numba.fingerprint(_numba.kernel_sources(here))
