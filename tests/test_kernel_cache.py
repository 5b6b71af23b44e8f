"""The compiled cache is dropped when any kernel source changes (numba alone misses a callee's)."""

from __future__ import annotations

import shutil
from pathlib import Path

from fault_tolerance import kernel_cache

PACKAGE = Path(kernel_cache.__file__).resolve().parent


def test_every_module_with_compiled_code_is_a_kernel_source():
    """A module that defines or inlines numba code is in KERNEL_SOURCES, and nothing else is."""
    compiled = {
        p.name
        for p in PACKAGE.glob("*.py")
        if "njit" in p.read_text(encoding="utf-8") and p.name != "kernel_cache.py"
    }
    assert compiled == set(kernel_cache.KERNEL_SOURCES)


def test_a_changed_callee_drops_the_whole_cache(tmp_path):
    """Copy the sources, stamp them, change one file: every cached .nbi/.nbc goes, once."""
    for name in kernel_cache.KERNEL_SOURCES:
        shutil.copy(PACKAGE / name, tmp_path / name)
    cache = tmp_path / "__pycache__"
    assert kernel_cache.refresh(tmp_path)  # no stamp yet: cleared and stamped
    (cache / "boxsolve.bounded_kernel-1.py311.nbi").write_text("old")
    (cache / "boxsolve.bounded_kernel-1.py311.1.nbc").write_text("old")
    (cache / "unrelated.cpython-311.pyc").write_text("kept")
    assert not kernel_cache.refresh(tmp_path)  # nothing changed: the cache stays
    assert len(list(cache.glob("*.nb?"))) == 2
    with open(tmp_path / "boxkernel.py", "a") as f:  # the callee changes, boxsolve.py does not
        f.write("\n# edited\n")
    assert kernel_cache.refresh(tmp_path)
    assert list(cache.glob("*.nb?")) == [] and (cache / "unrelated.cpython-311.pyc").exists()
    assert not kernel_cache.refresh(tmp_path)


def test_a_read_only_or_incomplete_folder_is_left_alone(tmp_path):
    """A source missing (or an unwritable folder): no error, nothing deleted."""
    assert kernel_cache.refresh(tmp_path) is False
