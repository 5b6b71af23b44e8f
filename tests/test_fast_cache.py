"""The compiled cache: one key for the content of every kernel source, shared by every install."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from fault_tolerance import fast_cache

PACKAGE = Path(fast_cache.__file__).resolve().parent


def _copy_sources(dst: Path) -> None:
    for path in fast_cache.kernel_sources(PACKAGE):
        target = dst / path.relative_to(PACKAGE)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, target)


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


def test_no_kernel_module_calls_numba_njit_itself():
    """Every kernel is made by fast_cache.njit / inline, so every one is cached under the key."""
    offenders = [
        p.relative_to(PACKAGE).as_posix()
        for p in fast_cache.kernel_sources(PACKAGE)
        if "numba.njit" in p.read_text(encoding="utf-8")
    ]
    assert offenders == []


def test_a_changed_callee_changes_the_key_and_file_times_do_not(tmp_path):
    """Edit one callee: the digest of all sources changes; touch every file: it does not."""
    _copy_sources(tmp_path)
    before = fast_cache.sources_digest(tmp_path)
    assert before == fast_cache.sources_digest(PACKAGE)  # the same content, another place
    for path in fast_cache.kernel_sources(tmp_path):  # a reinstall rewrites every file
        os.utime(path, (1, 1))
    assert fast_cache.sources_digest(tmp_path) == before
    callee = tmp_path / "resolution" / "fast" / "box_qp.py"
    with open(callee, "a") as f:  # the callee changes, its callers do not
        f.write("\n# edited\n")
    assert fast_cache.sources_digest(tmp_path) != before


def test_the_cache_root_follows_the_environment(tmp_path, monkeypatch):
    """FAULT_TOLERANCE_CACHE_DIR, else XDG_CACHE_HOME, else ~/.cache; the key is a folder below."""
    monkeypatch.setenv(fast_cache.CACHE_ENV, str(tmp_path / "a"))
    assert fast_cache.cache_folder() == tmp_path / "a" / fast_cache.cache_key()
    monkeypatch.delenv(fast_cache.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert fast_cache.cache_root() == tmp_path / "x" / "fault_tolerance" / "kernels"


_PROBE = """
import sys
from numba.core import event
compiled = []
class Listener(event.Listener):
    def on_start(self, e):
        compiled.append(e.data["dispatcher"].py_func.__name__)
    def on_end(self, e):
        pass
event.register("numba:compile", Listener())
from fault_tolerance.bench import warm
import fault_tolerance
print(fault_tolerance.__file__)
warm.GROUPS["floor"]()
print("compiled:", ",".join(compiled))
"""


def _probe(cwd: Path, env: dict) -> list[str]:
    res = subprocess.run([sys.executable, "-c", _PROBE], cwd=cwd, env=env, capture_output=True,
                         text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    return res.stdout.splitlines()


def test_a_copy_of_the_package_elsewhere_finds_the_kernels_compiled(tmp_path):
    """Compile the floor kernel from the checkout; a fresh copy of the package in another folder
    with new file times (a reinstall, a wheel) loads it from the cache and compiles nothing."""
    env = {**os.environ, fast_cache.CACHE_ENV: str(tmp_path / "cache")}
    env.pop("PYTHONPATH", None)
    first = _probe(PACKAGE.parent, {**env, "PYTHONPATH": str(PACKAGE.parent)})
    assert first[0].startswith(str(PACKAGE)) and "floor_kernel" in first[1]
    site = tmp_path / "site"
    shutil.copytree(PACKAGE, site / "fault_tolerance", ignore=shutil.ignore_patterns("__pycache__"))
    again = _probe(tmp_path, {**env, "PYTHONPATH": str(site)})
    assert again[0].startswith(str(site / "fault_tolerance"))
    assert again[1] == "compiled: "  # loaded from the shared cache
    key = fast_cache.cache_key()
    assert (tmp_path / "cache" / key / "fault_tolerance.control.fast.step").is_dir()
