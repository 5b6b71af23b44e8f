"""The first run: the fast path compiled once and said so; a cold ``simulate`` takes the reference."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from fault_tolerance import fast_cache
from fault_tolerance.bench import warm
from fault_tolerance.cli import simulate as cli_simulate
from fault_tolerance.errors import InvalidInput


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache root (FAULT_TOLERANCE_CACHE_DIR) for the markers; the default policy."""
    monkeypatch.setenv(fast_cache.CACHE_ENV, str(tmp_path))
    monkeypatch.delenv(warm.FIRST_RUN, raising=False)
    return tmp_path / fast_cache.cache_key()


def test_a_marker_holds_while_the_sources_do(cache, monkeypatch):
    """mark_warm writes a marker in the key's folder; it stops holding when the key changes."""
    assert not fast_cache.is_warm("controller")
    assert fast_cache.mark_warm("controller")
    assert fast_cache.is_warm("controller") and (cache / "warm-controller").is_file()
    monkeypatch.setattr(fast_cache, "cache_key", lambda: "other sources")
    assert not fast_cache.is_warm("controller")


def test_the_notice_is_one_line_with_its_progress():
    """Past the quiet time the notice says what compiles, counts the groups, ends the line once."""
    out = io.StringIO()
    notice = warm.Notice("compiling the fast path", 3, out, quiet=0.0)
    for _ in range(50):  # the timer thread shows the line
        if notice.shown:
            break
        time.sleep(0.02)
    notice.step()
    notice.step()
    notice.step()
    notice.close()
    text = out.getvalue()
    assert text.count("\n") == 1 and text.endswith(" s\n")
    assert text.startswith("fault-tolerance: compiling the fast path once (kernel group 1/3)…")
    assert " 2/3…" in text and " 3/3…" in text and "done in" in text


def test_a_kernel_in_the_cache_counts_as_compiled(cache, monkeypatch):
    """Without a marker, a group whose top-level kernels all have cached code is not cold."""
    assert not warm._cached("fault_tolerance.no_such_module", "kernel")
    monkeypatch.setattr(warm, "_cached", lambda module, name: True)
    assert warm.cold_groups(("controller", "simulate", "floor")) == ["floor"]  # floor: marker only
    monkeypatch.setattr(warm, "_cached", lambda module, name: name != "multi_kernel")
    assert warm.cold_groups(("controller", "multi", "bounded")) == ["multi"]


def test_a_quick_warm_says_nothing(cache, monkeypatch):
    """Groups done within the quiet time print nothing; they are marked, then skipped."""
    ran = []
    monkeypatch.setattr(
        warm, "GROUPS", {"a": lambda: ran.append("a"), "b": lambda: ran.append("b")}
    )
    out = io.StringIO()
    assert warm.warm(("a", "b"), stream=out) == ["a", "b"]
    assert ran == ["a", "b"] and out.getvalue() == ""
    assert warm.warm(("a", "b"), stream=out) == [] and ran == ["a", "b"]
    assert warm.warm(("a",), stream=out, force=True) == ["a"] and ran == ["a", "b", "a"]
    with pytest.raises(InvalidInput, match="not among"):
        warm.cold_groups(("nope",))


def test_the_engine_of_a_first_run(cache, monkeypatch):
    """Cold and short: the reference; cold and long: compile first."""
    monkeypatch.setattr(warm, "_cached", lambda module, name: False)  # an empty cache
    compiled = []
    monkeypatch.setattr(warm, "warm", lambda groups, **kw: compiled.append(tuple(groups)))
    short = SimpleNamespace(duration=2.0, dt=1e-3)
    assert cli_simulate.first_run_engine(short, 3) == "reference" and compiled == []
    long_ = SimpleNamespace(duration=100.0, dt=1e-3)
    assert cli_simulate.first_run_engine(long_, 3) == "auto"
    assert compiled == [("controller", "bounded", "simulate")]
    monkeypatch.setenv(warm.FIRST_RUN, "on-use")  # numba compiles on use, as before
    assert cli_simulate.first_run_engine(short, 3) == "auto" and len(compiled) == 1
    monkeypatch.setenv(warm.FIRST_RUN, "later")
    with pytest.raises(InvalidInput, match="FAULT_TOLERANCE_FIRST_RUN"):
        cli_simulate.first_run_engine(short, 3)
    monkeypatch.setenv(warm.FIRST_RUN, "ahead")
    for group in ("controller", "bounded", "simulate"):
        fast_cache.mark_warm(group)
    assert cli_simulate.first_run_engine(short, 3) == "auto"


def test_a_cold_simulate_compiles_nothing_says_so_and_leaves_no_process(tmp_path):
    """From an empty cache ``simulate`` succeeds, prints one notice line naming ``warm``, compiles
    nothing and starts no process that outlives it."""
    cache = tmp_path / "kernels"
    cache.mkdir()
    env = {**os.environ, fast_cache.CACHE_ENV: str(cache)}
    env[warm.FIRST_RUN] = "ahead"  # the default (the test suite's conftest sets on-use)
    cmd = [sys.executable, "-m", "fault_tolerance", "simulate", "--robot", "planar_3r"]
    cmd += ["--algorithms", "lnva,jvja", "--duration", "0.3", "--no-progress"]
    token = f"ft-test-{os.getpid()}-{time.monotonic_ns()}"
    env["FT_TEST_TOKEN"] = token  # inherited by anything the command starts
    res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.startswith("fault-tolerance:")]
    assert lines == [cli_simulate.REFERENCE_NOTICE] and "fault-tolerance warm" in lines[0]
    assert sorted(p.name for p in cache.rglob("*.nbi")) == []  # nothing was compiled
    assert _carrying(token) == []  # no process it started outlives it


def _carrying(token: str) -> list[int]:
    """Pids of the running processes whose environment holds ``FT_TEST_TOKEN=token`` (Linux)."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if f"FT_TEST_TOKEN={token}".encode() in environ.read_bytes().split(b"\0"):
                found.append(int(environ.parent.name))
        except OSError:  # gone, or not ours to read
            continue
    return found
