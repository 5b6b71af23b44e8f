"""Result folders are whole or absent: staged writes, completion records, folder locks."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from fault_tolerance.errors import FolderLocked, IncompleteResult, InvalidInput, OutputError
from fault_tolerance.storage import result_folder as results
from fault_tolerance.storage.folder_lock import FolderLock, in_progress, lock_holder
from fault_tolerance.storage.result_folder import RECORD, staged_folder, verify_folder

ROOT = Path(__file__).resolve().parents[1]


def write(folder: Path, files: dict[str, bytes]) -> None:
    """Write ``files`` (name -> bytes) into ``folder``."""
    for name, data in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)


def litter(parent: Path) -> list[str]:
    """Hidden staging folders and lock files left in ``parent``."""
    return sorted(p.name for p in parent.iterdir() if p.name.startswith("."))


def test_staged_folder_appears_whole_with_its_record(tmp_path):
    """The folder appears only on success, with every file listed (size, SHA-256) in complete.json."""
    target = tmp_path / "out" / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"a.bin": b"\x00" * 1000, "sub/b.txt": b"hello"})
        assert not target.exists()
        assert lock_holder(target)["pid"] == os.getpid()
    record = verify_folder(target)
    assert set(record["files"]) == {"a.bin", "sub/b.txt"}
    assert record["files"]["a.bin"]["bytes"] == 1000
    assert lock_holder(target) is None
    assert litter(target.parent) == []


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "two_renames"])
def test_an_existing_result_is_replaced_whole(tmp_path, monkeypatch, exchange):
    """A second write replaces the first whole (with and without renameat2), leaving no litter."""
    if not exchange:
        monkeypatch.setattr(results, "_RENAMEAT2", [None])
    target = tmp_path / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"old.txt": b"old", "same.txt": b"1"})
    with staged_folder(target) as tmp:
        write(tmp, {"same.txt": b"2"})
    assert sorted(p.name for p in target.iterdir()) == [RECORD, "same.txt"]
    assert (target / "same.txt").read_bytes() == b"2"
    verify_folder(target)
    assert litter(tmp_path) == []


@pytest.mark.parametrize(
    "exc", [OSError(28, "No space left on device"), KeyboardInterrupt(), RuntimeError("bug")]
)
def test_a_failing_write_leaves_the_old_result_and_no_litter(tmp_path, exc):
    """A write stopped midway (disk full, Ctrl-C, an error): the earlier result is as it was, the
    staged copy is gone; a disk error becomes the toolkit's OutputError (exit 2)."""
    target = tmp_path / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"x.txt": b"first"})
    expected = OutputError if isinstance(exc, OSError) else type(exc)
    with pytest.raises(expected):
        with staged_folder(target) as tmp:
            write(tmp, {"x.txt": b"second, half"})
            raise exc
    assert (target / "x.txt").read_bytes() == b"first"
    verify_folder(target)
    assert litter(tmp_path) == []


def test_foreign_files_are_never_replaced(tmp_path):
    """An existing folder with files that are not a result's is refused before anything is written."""
    target = tmp_path / "thesis"
    target.mkdir()
    (target / "chapter1.tex").write_text("precious")
    with pytest.raises(InvalidInput, match="chapter1.tex"):
        with staged_folder(target, replaceable={"run.npz"}) as tmp:
            write(tmp, {"run.npz": b"x"})
    assert (target / "chapter1.tex").read_text() == "precious"
    # files the caller names as its own (an old-format result) may be replaced
    (target / "chapter1.tex").unlink()
    (target / "run.npz").write_bytes(b"old format")
    with staged_folder(target, replaceable={"run.npz"}) as tmp:
        write(tmp, {"run.npz": b"new"})
    assert (target / "run.npz").read_bytes() == b"new"


@pytest.mark.parametrize("how", ["no_record", "truncated", "altered", "added", "removed", "junk"])
def test_verify_refuses_an_incomplete_or_altered_folder(tmp_path, how):
    """verify_folder refuses, in one line naming the folder, a folder without a record, with a
    truncated, altered, added or removed file, or with a record that is not one."""
    target = tmp_path / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"run.npz": b"A" * 100, "summary.json": b"{}"})
    if how == "no_record":
        (target / RECORD).unlink()
    elif how == "truncated":
        (target / "run.npz").write_bytes(b"A" * 50)
    elif how == "altered":
        (target / "run.npz").write_bytes(b"B" * 100)
    elif how == "added":
        (target / "mesh.dae").write_bytes(b"x")
    elif how == "removed":
        (target / "summary.json").unlink()
    else:
        (target / RECORD).write_text('{"files": 3}')
    with pytest.raises(IncompleteResult) as info:
        verify_folder(target)
    assert str(target) in str(info.value) and "\n" not in str(info.value)


def test_verify_checks_only_the_files_asked_for(tmp_path):
    """files=[...] hashes only those (a reader of run.npz need not hash a big replay.html)."""
    target = tmp_path / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"run.npz": b"A", "replay.html": b"B"})
    (target / "replay.html").write_bytes(b"C")
    verify_folder(target, files=["run.npz"])
    with pytest.raises(IncompleteResult, match="replay.html"):
        verify_folder(target)


# -- locks -----------------------------------------------------------------------------------------

HOLDER = textwrap.dedent(
    """
    import sys, time
    from fault_tolerance.storage.result_folder import FolderLock
    with FolderLock(sys.argv[1]):
        print("locked", flush=True)
        time.sleep(60)
    """
)


def _holder(folder: Path) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)], stdout=subprocess.PIPE, text=True, cwd=ROOT
    )
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    """While another process holds the lock, acquiring it raises FolderLocked with its pid and
    command; once that process is killed (-9), the stale lock is taken over at once."""
    folder = tmp_path / "out"
    proc = _holder(folder)
    try:
        with pytest.raises(FolderLocked) as info:
            FolderLock(folder).acquire()
        assert f"pid {proc.pid}" in str(info.value) and "-c" in str(info.value)
        assert lock_holder(folder)["pid"] == proc.pid
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert lock_holder(folder) is None
    with FolderLock(folder):
        assert lock_holder(folder)["pid"] == os.getpid()


def test_locks_are_reentrant_within_a_process(tmp_path):
    """The same process may take a lock it holds (a command locks --out, then saves into it)."""
    with FolderLock(tmp_path / "a"):
        with FolderLock(tmp_path / "a"):
            pass
        assert lock_holder(tmp_path / "a")["pid"] == os.getpid()
    assert lock_holder(tmp_path / "a") is None


WRITER = textwrap.dedent(
    """
    import sys, time
    from fault_tolerance.errors import FolderLocked
    from fault_tolerance.storage.result_folder import staged_folder
    me = sys.argv[2]
    try:
        with staged_folder(sys.argv[1]) as tmp:
            for i in range(20):
                (tmp / f"part{i}").write_text(me)
                time.sleep(0.005)
    except FolderLocked as err:
        print("locked", err)
        sys.exit(2)
    print("wrote")
    """
)


def test_concurrent_writers_never_mix(tmp_path):
    """Six processes write one folder at once: each either writes whole or is refused (exit 2);
    the folder is one writer's, complete and verified."""
    target = tmp_path / "out"
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(target), f"w{i}"],
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        for i in range(6)
    ]
    outs = [(p.wait(timeout=60), p.stdout.read()) for p in procs]
    assert all(rc in (0, 2) for rc, _ in outs), outs
    assert any(rc == 0 for rc, _ in outs)
    verify_folder(target)
    writers = {(target / f"part{i}").read_text() for i in range(20)}
    assert len(writers) == 1
    assert litter(tmp_path) == []


KILLED = textwrap.dedent(
    """
    import sys, time
    from fault_tolerance.storage.result_folder import staged_folder
    with staged_folder(sys.argv[1]) as tmp:
        (tmp / "a").write_text("new")
        print("writing", flush=True)
        time.sleep(60)
    """
)


def test_kill_9_while_writing_leaves_the_old_result_and_the_next_writer_cleans_up(tmp_path):
    """kill -9 mid-write: the earlier result stays whole; the staging copy and the lock of the dead
    writer are swept by the next writer."""
    target = tmp_path / "out"
    with staged_folder(target) as tmp:
        write(tmp, {"a": b"old"})
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED, str(target)], stdout=subprocess.PIPE, text=True, cwd=ROOT
    )
    assert proc.stdout.readline().strip() == "writing"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (target / "a").read_text() == "old"
    verify_folder(target)
    assert any(".tmp-" in n for n in litter(tmp_path))
    with staged_folder(target) as tmp:
        write(tmp, {"a": b"newer"})
    assert (target / "a").read_text() == "newer" and litter(tmp_path) == []


def test_in_progress_marker_stays_until_the_block_finishes(tmp_path):
    """in_progress.json is there while the block runs, gone after it, and kept after Ctrl-C."""
    with in_progress(tmp_path / "o", what="test"):
        marker = json.loads((tmp_path / "o" / "in_progress.json").read_text())
        assert marker["pid"] == os.getpid() and marker["what"] == "test"
    assert not (tmp_path / "o" / "in_progress.json").exists()
    with pytest.raises(KeyboardInterrupt):
        with in_progress(tmp_path / "o"):
            raise KeyboardInterrupt
    assert (tmp_path / "o" / "in_progress.json").exists()
    with pytest.raises(IncompleteResult, match="in_progress"):
        verify_folder(tmp_path / "o")


def test_names_too_long_for_the_file_system_are_refused(tmp_path):
    """A 300-byte folder name (NAME_MAX is 255 on common file systems) is a one-line InvalidInput."""
    with pytest.raises(InvalidInput, match="longer than this file system allows"):
        with staged_folder(tmp_path / ("x" * 300)):
            pass
    with pytest.raises(InvalidInput, match="NUL"):
        results.check_path_names("a\x00b")
    assert litter(tmp_path) == []


# -- a full file system ----------------------------------------------------------------------------


@pytest.fixture
def tiny_fs(tmp_path):
    """A 1 MiB tmpfs mounted in tmp_path (needs root and a kernel that allows the mount)."""
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({r.stderr.strip() or 'mount failed'})")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_file_system_leaves_the_old_result_and_says_so(tiny_fs):
    """On a full file system the write fails with one line (OutputError, no space), the earlier
    result stays whole and nothing is left behind."""
    target = tiny_fs / "run"
    with staged_folder(target) as tmp:
        write(tmp, {"a": b"old"})
    with pytest.raises(OutputError, match="no space left"):
        with staged_folder(target) as tmp:
            write(tmp, {"big": os.urandom(2 << 20)})
    assert (target / "a").read_bytes() == b"old"
    verify_folder(target)
    assert litter(tiny_fs) == []
