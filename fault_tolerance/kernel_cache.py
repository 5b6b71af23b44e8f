"""Keep numba's on-disk cache of the compiled kernels consistent with their sources.

numba keys a cached function by its own file only: a kernel in ``boxsolve.py`` that calls one in
``boxkernel.py`` keeps running the old callee after ``boxkernel.py`` changes. At import the
package compares the sizes and modification times of :data:`KERNEL_SOURCES` with the stamp it
wrote last; when they differ it deletes the package's ``__pycache__/*.nbi`` / ``*.nbc`` files (the
next call recompiles, ~5-10 s once) and writes the new stamp. A package folder that cannot be
written is left alone (numba then caches elsewhere or not at all).
"""

from __future__ import annotations

from pathlib import Path

#: Modules with compiled (numba) code, or code numba inlines into another module's kernel.
KERNEL_SOURCES = (
    "batch_kernel.py",
    "boxbasis.py",
    "boxcheck.py",
    "boxkernel.py",
    "boxsolve.py",
    "compiled_linalg.py",
    "multi_kernel.py",
    "rank_one_eigen.py",
    "sample_bounded.py",
    "sample_kernel.py",
    "sample_limits.py",
    "sample_linalg.py",
    "small_eigen.py",
    "single_kernel.py",
)
STAMP = "kernel_sources.stamp"


def stamp(folder: Path) -> str:
    """``name size mtime_ns`` of every kernel source, one per line."""
    lines = []
    for name in KERNEL_SOURCES:
        st = (folder / name).stat()
        lines.append(f"{name} {st.st_size} {st.st_mtime_ns}")
    return "\n".join(lines) + "\n"


def refresh(folder: Path | None = None) -> bool:
    """Delete the compiled cache when a kernel source changed since the last stamp; True if so."""
    folder = Path(__file__).resolve().parent if folder is None else folder
    cache = folder / "__pycache__"
    try:
        now = stamp(folder)
    except OSError:  # a kernel source missing: not this package's layout, nothing to do
        return False
    try:
        if (cache / STAMP).read_text() == now:
            return False
    except OSError:  # no stamp yet
        pass
    try:
        cache.mkdir(exist_ok=True)
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink(missing_ok=True)
        (cache / STAMP).write_text(now)
    except OSError:  # a read-only install
        return False
    return True
