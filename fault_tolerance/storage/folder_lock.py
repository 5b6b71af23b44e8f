"""Who writes a result folder: an advisory lock per folder, and the mark of a folder being filled.

:class:`FolderLock` is an advisory lock (``flock``) on a hidden sibling ``.NAME.lock`` while a
command writes ``NAME``; a second writer gets :class:`~.errors.FolderLocked` naming the holder's
pid and command. The kernel drops the lock when its holder dies (even by ``kill -9``), so a lock
left by a dead process is taken over at once. Locks are re-entrant within one process.
:func:`in_progress` marks a folder that accumulates results (``reproduce --out``) while a command
fills it. Both are importable from :mod:`.results` too.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import stat
import time
from collections.abc import Iterator
from pathlib import Path

from fault_tolerance.errors import FolderLocked, InvalidInput, OutputError
from fault_tolerance.storage.folder_io import (
    READ_FILE,
    check_path_names,
    command_line,
    output_error,
    refuse_link,
    write_synced,
)

#: The marker of a folder a command is still filling (see :func:`in_progress`).
IN_PROGRESS = "in_progress.json"


_held: dict[str, list] = {}  # lock path -> [fd, depth], locks this process holds


class FolderLock:
    """Exclusive, advisory lock on writing ``folder``: ``with FolderLock(out): ...``.

    The lock is ``flock`` on the hidden sibling ``.NAME.lock`` (or ``NAME/.lock`` when the parent is
    not writable), which holds the holder's pid, command and start time. A live holder makes
    :meth:`acquire` raise :class:`~.errors.FolderLocked` at once; a dead one's lock is gone with its
    process. Re-entrant within one process.
    """

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.path = lock_path(self.folder)

    def acquire(self) -> FolderLock:
        """Take the lock, or raise :class:`~.errors.FolderLocked` naming the holder."""
        key = str(self.path)
        if key in _held:
            _held[key][1] += 1
            return self
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(20):  # retry only if the file was replaced between open and flock
            fd = _open_lock(self.path, self.folder)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                info = _read_holder(fd)
                os.close(fd)
                raise FolderLocked(self.folder, info) from None
            try:
                same = os.fstat(fd).st_ino == os.lstat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # the holder removed it as we opened it; take the new file
                os.close(fd)
                continue
            info = {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "command": command_line(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            }
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
            _held[key] = [fd, 1]
            return self
        raise OutputError(f"{self.folder}: could not take the lock {self.path}")  # pragma: no cover

    def release(self) -> None:
        """Give the lock back (the lock file is removed when the outermost holder releases)."""
        key = str(self.path)
        entry = _held.get(key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] > 0:
            return
        del _held[key]
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(entry[0])

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _open_lock(path: Path, folder: Path) -> int:
    """Open (create) the lock file: a regular file, never through a link nor a FIFO."""
    refuse_link(path)
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as err:
        if err.errno == errno.ELOOP:  # became a link between the check and the open
            refuse_link(path)
        raise output_error(err, folder) from err
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        refuse_link(path)  # names what it is
        raise OutputError(f"{path}: the lock is not a regular file")  # pragma: no cover
    return fd


def lock_path(folder: str | Path) -> Path:
    """Where the lock of ``folder`` lives: ``.NAME.lock`` beside it, or inside if the parent is read-only."""
    folder = Path(os.path.abspath(folder))
    parent = folder.parent
    if parent.exists() and not os.access(parent, os.W_OK | os.X_OK) and folder.is_dir():
        return folder / ".lock"
    return parent / f".{folder.name}.lock"


def lock_holder(folder: str | Path) -> dict | None:
    """Who holds the lock of ``folder`` (pid, host, command, started), or None if nobody does."""
    path = lock_path(folder)
    try:
        fd = os.open(path, READ_FILE)
    except OSError:
        return None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_holder(fd)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _read_holder(fd: int) -> dict:
    try:
        raw = os.pread(fd, 4096, 0)
        info = json.loads(raw.decode("utf-8", "replace") or "{}")
        return info if isinstance(info, dict) else {}
    except (OSError, ValueError):
        return {}


# -- a folder being filled -------------------------------------------------------------------


@contextlib.contextmanager
def in_progress(folder: str | Path, **info) -> Iterator[Path]:
    """Lock ``folder`` and mark it with ``in_progress.json`` until the block ends without error.

    For folders that accumulate results (``reproduce --out``): the marker says a command is filling
    it (pid, command, start); it is removed when the block finishes, and kept when the block is
    stopped (Ctrl-C, an error) or killed, so a reader knows the folder's top-level summary is not
    the final one of this command.
    """
    folder = check_path_names(Path(folder))
    if folder.exists() and not folder.is_dir():
        raise InvalidInput(f"{folder}: exists and is not a folder; choose a folder for the output")
    refuse_link(folder, folder=True)
    with FolderLock(folder):
        marker = refuse_link(folder / IN_PROGRESS)
        text = {
            "pid": os.getpid(),
            "command": command_line(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            **info,
        }
        try:
            folder.mkdir(parents=True, exist_ok=True)
            write_synced(folder / f".{IN_PROGRESS}.tmp", (json.dumps(text) + "\n").encode())
            os.replace(folder / f".{IN_PROGRESS}.tmp", marker)
        except OSError as err:
            raise output_error(err, folder) from err
        yield folder
        marker.unlink(missing_ok=True)
