"""Result folders on the command line: whole or absent under concurrent writers, kill -9, a full disk.

Every check runs the real command (``python -m fault_tolerance``) in a subprocess, kills or races it,
and then reads what is on disk the way a user would: ``Run.load`` (which verifies the completion
record) and ``replay``.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fault_tolerance.storage.folder_lock import lock_holder
from fault_tolerance.storage.result_folder import RECORD, verify_folder

ROOT = Path(__file__).resolve().parents[1]
SIM = ["simulate", "--robot", "planar_3r", "--no-progress"]


def start(args: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "fault_tolerance", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )


def run(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fault_tolerance", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
    )


def wait_until(cond, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if proc.poll() is not None:
            pytest.fail(f"the command ended first: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail("timed out")
        time.sleep(0.01)


def run_folders(out: Path) -> list[Path]:
    """Visible subfolders of ``out`` (hidden ones are staging copies, swept by the next writer)."""
    if not out.exists():
        return []
    return sorted(p for p in out.iterdir() if p.is_dir() and not p.name.startswith("."))


def assert_whole(folder: Path) -> None:
    """The folder verifies against its record, loads, and replays (exit 0)."""
    from fault_tolerance.simulation.run import Run

    verify_folder(folder)
    Run.load(folder)
    r = run(["replay", str(folder), "--html", str(folder.parent / f".{folder.name}.check.html")])
    assert r.returncode == 0, r.stderr
    (folder.parent / f".{folder.name}.check.html").unlink()


def test_a_second_writer_of_the_same_folder_gets_exit_2_naming_the_first(tmp_path):
    """Two `simulate --out DIR` at once: the second exits 2 at once naming the first's pid and
    command; the first finishes, and DIR holds only its runs, each whole."""
    out = tmp_path / "out"
    first = start(SIM + ["--algorithms", "lnva,jvja", "--duration", "3", "--out", str(out)])
    wait_until(lambda: lock_holder(out) is not None, first)
    second = run(SIM + ["--algorithms", "mda", "--duration", "0.01", "--out", str(out)])
    assert second.returncode == 2, second.stderr
    assert f"pid {first.pid}" in second.stderr and "simulate" in second.stderr
    assert second.stderr.count("\n") == 1
    assert first.wait(timeout=300) == 0, first.stderr.read()
    assert [p.name for p in run_folders(out)] == ["jvja", "lnva"]
    for folder in run_folders(out):
        verify_folder(folder)
    assert lock_holder(out) is None


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_kill_9_during_simulate_leaves_whole_runs_and_a_rerun_works(tmp_path, seed):
    """simulate killed (-9) at a random moment: each run folder present is whole (verifies, loads,
    replays); none is half written; a rerun into the same folder succeeds and cleans up."""
    out = tmp_path / "out"
    args = SIM + ["--algorithms", "lnva,jvja,mda", "--duration", "1", "--out", str(out)]
    proc = start(args)
    wait_until(lambda: lock_holder(out) is not None, proc)
    time.sleep(random.Random(seed).uniform(0.0, 4.0))
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    for folder in run_folders(out):
        assert_whole(folder)
    rerun = run(args)
    assert rerun.returncode == 0, rerun.stderr
    assert [p.name for p in run_folders(out)] == ["jvja", "lnva", "mda"]
    for folder in run_folders(out):
        verify_folder(folder)
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and p.is_dir()]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3])
def test_kill_9_during_reproduce_then_replay_and_rerun(tmp_path, seed):
    """reproduce killed (-9) at a random moment: the folder says it is in progress, the run folders
    present are whole and replay, summary.json is absent or an earlier one; a rerun finishes and
    removes the marker."""
    out = tmp_path / "rep"
    args = ["reproduce", "--quick", "--no-progress", "--cases", "fig2", "--out", str(out)]
    proc = start(args)
    wait_until(lambda: (out / "in_progress.json").exists(), proc)
    time.sleep(random.Random(seed).uniform(0.0, 6.0))
    proc.send_signal(signal.SIGKILL)
    finished = proc.wait() == 0
    if not finished:
        assert (out / "in_progress.json").exists()
        assert not (out / "summary.json").exists()
    runs = out / "runs" / "fig2"
    for folder in run_folders(runs) if runs.exists() else []:
        assert_whole(folder)
    rerun = run(args, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert not (out / "in_progress.json").exists()
    assert json.loads((out / "summary.json").read_text())["cases"]["fig2"]
    for folder in run_folders(runs):
        verify_folder(folder)


# -- a full file system ----------------------------------------------------------------------------


@pytest.fixture
def tiny_fs(tmp_path):
    """A 2 MiB tmpfs (needs root and a kernel that allows the mount; else the test is skipped)."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True, text=True
    )
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({r.stderr.strip() or 'mount failed'})")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(mnt: Path, leave: int) -> None:
    """Fill the file system ``mnt`` until about ``leave`` bytes are free."""
    st = os.statvfs(mnt)
    free = st.f_bavail * st.f_frsize
    with open(mnt / "filler", "wb") as fh:
        fh.write(b"\x00" * max(0, free - leave))


@pytest.mark.slow
@pytest.mark.parametrize("command", ["simulate", "lock"])
def test_a_full_disk_gives_exit_2_and_leaves_the_earlier_result(tiny_fs, command):
    """With the disk full, the command exits 2 with one line saying so; the earlier result (written
    when there was room) is whole and replays; no half-written folder or litter is left."""
    out = tiny_fs / "out"
    args = (
        SIM + ["--algorithms", "lnva", "--duration", "0.05", "--out", str(out)]
        if command == "simulate"
        else ["lock", "--robot", "planar_3r", "--joint", "joint2", "--at", "0.02", "--no-progress"]
        + ["--duration", "0.05", "--out", str(out)]
    )
    first = run(args)
    assert first.returncode == 0, first.stderr
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    fill(tiny_fs, leave=20_000)
    second = run(args)
    assert second.returncode == 2, second.stderr
    assert "no space left" in second.stderr and second.stderr.count("\n") == 1
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    (tiny_fs / "filler").unlink()
    folder = out / "lnva" if command == "simulate" else out
    assert (folder / RECORD).exists()
    assert_whole(folder)
    assert not [p.name for p in tiny_fs.rglob(".*") if p.is_dir()]


@pytest.mark.parametrize("command", ["workspace", "design"])
def test_workspace_and_design_refuse_a_second_writer(tmp_path, command):
    """workspace / design --out DIR while another process writes DIR: exit 2 naming its pid."""
    out = tmp_path / "ws"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom fault_tolerance.storage.result_folder import FolderLock\n"
         "with FolderLock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(60)",
         str(out)],
        stdout=subprocess.PIPE, text=True, cwd=ROOT,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "locked"
        r = run([command, "--robot", "planar_3r", "--no-progress", "--out", str(out)])
        assert r.returncode == 2 and f"pid {holder.pid}" in r.stderr, r.stderr
        assert r.stderr.count("\n") == 1
    finally:
        holder.kill()
        holder.wait()
