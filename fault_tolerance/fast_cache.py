"""Keep numba's on-disk cache of the compiled kernels consistent with their sources.

numba keys a cached function by its own file only: a kernel in ``control/fast/bounded_solve.py``
that calls one in ``resolution/fast/box_qp.py`` keeps running the old callee after the callee
changes. At import the package compares the sizes and modification times of every module in a
``fast/`` folder with the stamp it wrote last; when they differ it deletes the package's
``__pycache__/*.nbi`` / ``*.nbc`` files in every folder (the
next call recompiles, ~5-10 s once) and writes the new stamp. A package folder that cannot be
written is left alone (numba then caches elsewhere or not at all).

:func:`is_warm` / :func:`mark_warm` keep one marker per group of kernels (``warm-<group>``) beside
numba's cache (``NUMBA_CACHE_DIR`` when set, else the package's ``__pycache__``): written once the
group was compiled into the cache, valid while the kernel sources, numba and Python are those it
names. The command line reads them to know whether a command would compile first
(:mod:`fault_tolerance.bench.warm`).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: Where compiled (numba) code lives: every module in a ``fast/`` folder of the package.
FAST_FOLDER = "fast"
STAMP = "kernel_sources.stamp"
_PACKAGE = Path(__file__).resolve().parent


def kernel_sources(folder: Path) -> list[Path]:
    """The modules with compiled code: every ``.py`` in a ``fast/`` folder below ``folder``."""
    return sorted(p for p in folder.rglob("*.py") if p.parent.name == FAST_FOLDER)


def stamp(folder: Path) -> str:
    """``path size mtime_ns`` of every kernel source, one per line."""
    lines = []
    for path in kernel_sources(folder):
        st = path.stat()
        lines.append(f"{path.relative_to(folder).as_posix()} {st.st_size} {st.st_mtime_ns}")
    return "\n".join(lines) + "\n"


def refresh(folder: Path | None = None) -> bool:
    """Delete the compiled cache when a kernel source changed since the last stamp; True if so."""
    folder = Path(__file__).resolve().parent if folder is None else folder
    cache = folder / "__pycache__"
    try:
        now = stamp(folder)
    except OSError:  # a kernel source vanished while read: nothing to do
        return False
    if now == "\n":  # no fast/ folder: not this package's layout
        return False
    try:
        if (cache / STAMP).read_text() == now:
            return False
    except OSError:  # no stamp yet
        pass
    try:
        cache.mkdir(exist_ok=True)
        for f in list(folder.rglob("*.nbi")) + list(folder.rglob("*.nbc")):
            f.unlink(missing_ok=True)
        (cache / STAMP).write_text(now)
    except OSError:  # a read-only install
        return False
    return True


def cache_folder(folder: Path | None = None) -> Path:
    """Where numba caches the package's kernels: ``NUMBA_CACHE_DIR``, else ``__pycache__``."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    return Path(env) if env else (_PACKAGE if folder is None else folder) / "__pycache__"


def warm_key(folder: Path | None = None) -> str:
    """What a warm marker must name: numba's and Python's versions and the kernel sources."""
    try:
        import numba

        version = numba.__version__
    except ImportError:  # pragma: no cover - numba is a core dependency
        version = "none"
    folder = _PACKAGE if folder is None else folder
    return f"numba {version} python {sys.version.split()[0]}\n" + stamp(folder)


def is_warm(group: str, folder: Path | None = None) -> bool:
    """Whether the kernels of ``group`` were compiled into the cache for these sources."""
    try:
        return (cache_folder(folder) / f"warm-{group}").read_text() == warm_key(folder)
    except OSError:
        return False


def mark_warm(group: str, folder: Path | None = None) -> bool:
    """Record that ``group`` is compiled into the cache; False where it cannot be written."""
    target = cache_folder(folder)
    try:
        target.mkdir(parents=True, exist_ok=True)
        tmp = target / f".warm-{group}.{os.getpid()}"
        tmp.write_text(warm_key(folder))
        tmp.replace(target / f"warm-{group}")
    except OSError:
        return False
    return True
