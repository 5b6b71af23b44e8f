"""The compiled kernels' decorator and their on-disk cache, keyed on the content of their sources.

Every numba kernel of the package is made by :func:`njit` (or :func:`inline`): compiled at its
first call, then cached on disk. numba keys a cached kernel on its own file only, so a kernel that
calls one in another file would keep running the old callee after the callee changed, and its
cache lives beside the installed sources, so a wheel and a checkout of the same code each
compile it again. The package therefore puts every kernel's cache in one folder per *key*::

    <root>/<key>/<module>/<numba's files>

where ``key`` is a SHA-256 of the content of every kernel source (every module in a ``fast/``
folder, with its path in the package), numba's and Python's versions. Any change to any kernel
source gives a new key, so a callee's change reaches its callers; a reinstall (``pip install
.`` and then ``pip install '.[notebooks]'``), a wheel, an editable checkout and a copy of the
package with the same sources share one compiled cache. ``root`` is, in order:
``FAULT_TOLERANCE_CACHE_DIR``, ``$XDG_CACHE_HOME/fault_tolerance/kernels``,
``~/.cache/fault_tolerance/kernels``. Where it cannot be written numba's own places are used
(``NUMBA_CACHE_DIR``, the package's ``__pycache__``), keyed as numba keys them.

:func:`is_warm` / :func:`mark_warm` keep one marker per group of kernels (``warm-<group>``) in the
key's folder: written once the group was compiled into the cache, so the command line knows
whether a command would compile first (:mod:`fault_tolerance.bench.warm`). Importing this module
imports no numba; :func:`njit` does, at the first kernel's definition.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
from collections.abc import Callable
from functools import cache, lru_cache
from pathlib import Path
from typing import Any

#: Where compiled (numba) code lives: every module in a ``fast/`` folder of the package.
FAST_FOLDER = "fast"
#: The environment variable that chooses the cache's root folder.
CACHE_ENV = "FAULT_TOLERANCE_CACHE_DIR"
_PACKAGE = Path(__file__).resolve().parent
#: Whether numba is installed: the kernels are compiled (else they run as plain Python).
COMPILED = importlib.util.find_spec("numba") is not None


def kernel_sources(folder: Path = _PACKAGE) -> list[Path]:
    """The modules with compiled code: every ``.py`` in a ``fast/`` folder below ``folder``."""
    return sorted(p for p in folder.rglob("*.py") if p.parent.name == FAST_FOLDER)


def sources_digest(folder: Path = _PACKAGE) -> str:
    """SHA-256 of every kernel source's path (in ``folder``) and content, in order."""
    h = hashlib.sha256()
    for path in kernel_sources(folder):
        h.update(path.relative_to(folder).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


@lru_cache(maxsize=1)
def cache_key() -> str:
    """The folder name of this package's compiled cache: sources, numba and Python (16 hex digits)."""
    try:
        import numba

        version = numba.__version__
    except ImportError:  # pragma: no cover - numba is a core dependency
        version = "none"
    h = hashlib.sha256(f"numba {version} python {sys.version}\n".encode())
    h.update(sources_digest().encode())
    return h.hexdigest()[:16]


def cache_root() -> Path:
    """The root of the package's kernel caches (``FAULT_TOLERANCE_CACHE_DIR`` or the user's cache)."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "fault_tolerance" / "kernels"


def cache_folder() -> Path:
    """The folder of the current sources' compiled cache and markers: ``<root>/<key>``."""
    return cache_root() / cache_key()


def _locator_class() -> type:
    """Numba's cache locator for the package's kernels: ``<root>/<key>/<module>``."""
    from numba.core.caching import _CacheLocator, _SourceFileBackedLocatorMixin

    class KernelCacheLocator(_SourceFileBackedLocatorMixin, _CacheLocator):
        """Caches a kernel of the package under the key of all its kernel sources."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = str(cache_folder() / py_func.__module__)

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            return cache_key()  # every kernel source at once: a callee's change reaches callers

        @classmethod
        def from_function(cls, py_func, py_file):
            module = getattr(py_func, "__module__", "") or ""
            if not module.startswith("fault_tolerance."):
                return None
            return super().from_function(py_func, py_file)  # None where it cannot be written

    return KernelCacheLocator


@lru_cache(maxsize=1)
def use_package_cache() -> bool:
    """Put :class:`KernelCacheLocator` first in numba's locators (once); False where it cannot."""
    try:
        from numba.core.caching import CacheImpl
    except ImportError:  # pragma: no cover - numba moved its caching module
        return False
    locators: list[Any] = CacheImpl._locator_classes  # numba's own list, read at each kernel
    if not any(getattr(c, "__name__", "") == "KernelCacheLocator" for c in locators):
        locators.insert(0, _locator_class())
    return True


@cache
def _compiler(inlined: bool) -> Callable:
    """The decorator of the package's kernels: cached, without the GIL, NumPy's error model."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a core dependency

        def plain(fn):
            return fn

        return plain
    use_package_cache()
    if inlined:
        return numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
    return numba.njit(cache=True, nogil=True, error_model="numpy")


def njit(fn: Callable) -> Any:
    """``fn`` compiled by numba at its first call, cached under :func:`cache_folder`.

    Plain Python without numba (and tested so).
    """
    return _compiler(False)(fn)


def inline(fn: Callable) -> Any:
    """As :func:`njit`, inlined into its compiled callers at numba's IR level."""
    return _compiler(True)(fn)


def is_warm(group: str) -> bool:
    """Whether the kernels of ``group`` were compiled into the cache of these sources."""
    return (cache_folder() / f"warm-{group}").is_file()


def mark_warm(group: str) -> bool:
    """Record that ``group`` is compiled into the cache; False where it cannot be written."""
    target = cache_folder()
    try:
        target.mkdir(parents=True, exist_ok=True)
        tmp = target / f".warm-{group}.{os.getpid()}"
        tmp.write_text(cache_key() + "\n")
        tmp.replace(target / f"warm-{group}")
    except OSError:
        return False
    return True
