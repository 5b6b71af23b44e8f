"""No lost work: atomic writes, and Ctrl-C during `reproduce` or `simulate` keeps what is finished."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import default_sigint

import fault_tolerance as ft
import fault_tolerance.paper.reproduce as experiments
import fault_tolerance.simulation.simulate as simulation
import fault_tolerance.storage.atomic as files
from fault_tolerance.simulation.run import Run
from fault_tolerance.storage.atomic import write_atomic

OLD = b"the previous, complete content\n"


def leftovers(folder: Path) -> list[str]:
    """Temporary files write_atomic may have left behind."""
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


class _HalfWriter:
    """A file object that writes half of what it is given, then fails."""

    def __init__(self, fh, exc):
        self.fh, self.exc = fh, exc

    def write(self, data):
        self.fh.write(data[: len(data) // 2])
        self.fh.flush()
        raise self.exc

    def __getattr__(self, name):
        return getattr(self.fh, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.fh.close()


@pytest.mark.parametrize(
    "exc",
    [OSError(28, "No space left on device"), KeyboardInterrupt()],
    ids=["disk_full", "ctrl_c"],
)
@pytest.mark.parametrize("existing", [True, False])
def test_write_failing_midway_leaves_no_partial_file(tmp_path, monkeypatch, exc, existing):
    """A write that fails halfway (disk full, Ctrl-C) leaves the old file as it was (or no file),
    no temporary file, and the exception goes on."""
    target = tmp_path / "summary.json"
    if existing:
        target.write_bytes(OLD)
    real = os.fdopen
    monkeypatch.setattr(files.os, "fdopen", lambda fd, mode: _HalfWriter(real(fd, mode), exc))
    with pytest.raises(type(exc)):
        write_atomic(target, b"x" * 100_000)
    monkeypatch.undo()
    assert (target.read_bytes() == OLD) if existing else not target.exists()
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("step", ["fsync", "replace"])
def test_failure_in_fsync_or_rename_keeps_the_old_file(tmp_path, monkeypatch, step):
    """fsync or the final rename failing: old content intact, no temporary file left."""
    target = tmp_path / "run.csv"
    target.write_bytes(OLD)

    def fail(*args, **kwargs):
        raise OSError(5, f"{step} failed")

    monkeypatch.setattr(files.os, step, fail)
    with pytest.raises(OSError, match=f"{step} failed"):
        write_atomic(target, "new content")
    monkeypatch.undo()
    assert target.read_bytes() == OLD
    assert leftovers(tmp_path) == []


def test_write_atomic_replaces_the_whole_file(tmp_path):
    """A successful write replaces the file at once, text or bytes, creating folders."""
    target = tmp_path / "deep" / "er" / "f.txt"
    write_atomic(target, "é\n")
    assert target.read_text(encoding="utf-8") == "é\n"
    write_atomic(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01" and leftovers(target.parent) == []


def test_run_save_failing_on_the_last_file_keeps_the_earlier_run_whole(
    tmp_path, planar_3r, monkeypatch
):
    """A save that fails on summary.json (the last file, disk full): the folder still holds the
    earlier run, whole (it loads, its record verifies), and nothing of the new one; the disk error
    is the toolkit's one-line OutputError."""
    from fault_tolerance.errors import OutputError
    from fault_tolerance.storage.result_folder import verify_folder

    path = experiments.CASES["fig2"].path(0.02)
    first = simulation.simulate(planar_3r.arm, path, "lnva", q0=np.array([0.3, 1.2, 1.0]))
    second = simulation.simulate(planar_3r.arm, path, "jvja", q0=np.array([0.3, 1.2, 1.0]))
    folder = tmp_path / "run"
    first.save(folder)

    def full(self):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Run, "summary", full)
    with pytest.raises(OutputError, match="no space left"):
        second.save(folder)
    monkeypatch.undo()
    verify_folder(folder)
    assert Run.load(folder).meta["algorithm"] == "lnva"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


@pytest.mark.parametrize(
    "stop", [KeyboardInterrupt(), ft.IntolerableFailure(["joint3"], 0.0)], ids=["ctrl_c", "error"]
)
def test_reproduce_stopped_keeps_finished_cases_and_says_what_is_missing(
    tmp_path, monkeypatch, stop
):
    """reproduce stopped in its second case (Ctrl-C or an error): the first case's files are
    complete, summary.partial.json lists finished / unfinished cases and what stopped it, an
    earlier summary.json is unchanged, and the exception goes on."""
    (tmp_path / "summary.json").write_bytes(OLD)
    real = experiments.run_case

    def run_case(case, **kw):
        if case.key == "fig4":
            raise stop
        return real(case, **kw)

    monkeypatch.setattr(experiments, "run_case", run_case)
    with pytest.raises(type(stop)):
        experiments.reproduce(
            tmp_path, cases=["fig2", "fig4", "experiment"], quick=True, progress=False
        )
    partial = json.loads((tmp_path / "summary.partial.json").read_text())
    assert partial["finished"] == ["fig2"]
    assert partial["unfinished"] == ["fig4", "experiment", "checks"]
    assert ("interrupted" in partial["stopped_by"]) == isinstance(stop, KeyboardInterrupt)
    assert "fig2" in partial["cases"]
    assert (tmp_path / "summary.json").read_bytes() == OLD
    for alg in ("lnva", "jvja", "mda"):
        assert Run.load(tmp_path / "runs" / "fig2" / alg).meta["algorithm"] == alg
    assert not list(tmp_path.rglob("*.tmp"))


# -- Ctrl-C on the command line ------------------------------------------------------------------


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "fault_tolerance", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        if proc.poll() is not None:
            pytest.fail(f"the command ended before {path.name} appeared: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"{path} did not appear within {timeout} s")
        time.sleep(0.02)


def test_ctrl_c_during_reproduce(tmp_path):
    """SIGINT after the first case is written: exit code 130, one line saying where the finished
    cases are and what is listed as unfinished, finished files intact, summary.json unchanged."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_bytes(OLD)
    proc = _start(
        ["reproduce", "--quick", "--no-progress", "--out", str(out), "--cases", "fig2,experiment"],
        tmp_path,
    )
    _wait_for(out / "runs" / "fig2" / "mda" / "summary.json", proc)
    time.sleep(0.3)  # well inside the experiment's runs (several seconds)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.count("\n") == 1 and "Traceback" not in stderr
    assert "interrupted" in stderr and "summary.partial.json" in stderr
    assert (out / "summary.json").read_bytes() == OLD
    partial = json.loads((out / "summary.partial.json").read_text())
    assert partial["finished"] == ["fig2"] and "experiment" in partial["unfinished"]
    for alg in ("lnva", "jvja", "mda"):
        run = Run.load(out / "runs" / "fig2" / alg)
        assert len(run.t) == 251 and np.all(np.isfinite(run.q))
    assert (out / "fig2.png").stat().st_size > 0
    assert not list(out.rglob("*.tmp"))


def test_ctrl_c_during_simulate(tmp_path):
    """SIGINT during the second algorithm of `simulate`: exit code 130, one line naming the
    finished and unfinished runs; the finished run is complete on disk."""
    out = tmp_path / "sim"
    proc = _start(
        [
            "simulate",
            "--robot",
            "planar_3r",
            "--algorithms",
            "lnva,mda",
            "--duration",
            "20",
            "--no-progress",
            "--out",
            str(out),
        ],
        tmp_path,
    )
    _wait_for(out / "lnva" / "summary.json", proc)
    time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.count("\n") == 1 and "Traceback" not in stderr
    assert "finished ['lnva'], not finished ['mda']" in stderr
    run = Run.load(out / "lnva")
    assert len(run.t) == 20_001 and run.meta["algorithm"] == "lnva"
    assert not (out / "mda").exists() or not (out / "mda" / "run.npz").exists()
    assert not list(out.rglob("*.tmp"))
