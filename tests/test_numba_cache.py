"""numba's cache is emptied when a source changed: a compiled caller keeps its callees' old
code, and a stale one crashed runs (segmentation fault) after the records changed."""

from __future__ import annotations

from dftc_mujoco import numba_cache


def test_a_changed_source_empties_the_cache_once(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub" / "__pycache__").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    cached = [pkg / "__pycache__" / "a.f-1.py311.nbi", pkg / "sub" / "__pycache__" / "b.g.nbc"]
    for c in cached:
        c.write_bytes(b"old")
    assert numba_cache.refresh(pkg)  # no stamp yet: whatever is cached is of unknown age
    assert not any(c.exists() for c in cached)
    for c in cached:
        c.write_bytes(b"fresh")
    assert not numba_cache.refresh(pkg)  # nothing changed: the cache stays
    assert all(c.exists() for c in cached)
    (pkg / "sub" / "b.py").write_text("y = 3  # edited\n")
    assert numba_cache.refresh(pkg)
    assert not any(c.exists() for c in cached)
    assert (pkg / "a.py").exists() and (pkg / "sub" / "b.py").exists()  # sources untouched
