"""The compiled cache is dropped when any kernel source changes (numba alone misses a callee's)."""

from __future__ import annotations

import shutil
from pathlib import Path

from fault_tolerance import fast_cache

PACKAGE = Path(fast_cache.__file__).resolve().parent


def test_every_module_with_compiled_code_is_in_a_fast_folder():
    """A module that defines numba code lives in a fast/ folder, and every fast/ module is a source."""
    compiled = {
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*.py")
        if "njit" in p.read_text(encoding="utf-8") and p.name != "fast_cache.py"
    }
    sources = {p.relative_to(PACKAGE).as_posix() for p in fast_cache.kernel_sources(PACKAGE)}
    assert compiled and compiled <= sources
    assert all("/fast/" in f"/{name}" for name in sources)


def test_a_changed_callee_drops_the_whole_cache(tmp_path):
    """Copy the sources, stamp them, change one file: every cached .nbi/.nbc goes, once."""
    for path in fast_cache.kernel_sources(PACKAGE):
        dst = tmp_path / path.relative_to(PACKAGE)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, dst)
    cache = tmp_path / "control" / "fast" / "__pycache__"
    assert fast_cache.refresh(tmp_path)  # no stamp yet: cleared and stamped
    cache.mkdir(parents=True)
    (cache / "bounded_solve.bounded_kernel-1.py311.nbi").write_text("old")
    (cache / "bounded_solve.bounded_kernel-1.py311.1.nbc").write_text("old")
    (cache / "unrelated.cpython-311.pyc").write_text("kept")
    assert not fast_cache.refresh(tmp_path)  # nothing changed: the cache stays
    assert len(list(cache.glob("*.nb?"))) == 2
    callee = tmp_path / "resolution" / "fast" / "box_qp.py"
    with open(callee, "a") as f:  # the callee changes, bounded_solve.py does not
        f.write("\n# edited\n")
    assert fast_cache.refresh(tmp_path)
    assert list(cache.glob("*.nb?")) == [] and (cache / "unrelated.cpython-311.pyc").exists()
    assert not fast_cache.refresh(tmp_path)


def test_a_folder_without_kernels_is_left_alone(tmp_path):
    """No fast/ folder (not this package's layout): no error, nothing written."""
    assert fast_cache.refresh(tmp_path) is False
    assert not (tmp_path / "__pycache__").exists()
