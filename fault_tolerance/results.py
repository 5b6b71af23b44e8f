"""Result folders that are whole or absent: staged writes, a completion record, a folder lock.

Three pieces, usable by every command that writes results (a run, a reproduce case, a workspace
chunk):

* :func:`staged_folder` — write a folder aside (a hidden sibling ``.NAME.tmp-XXXX``) and move it
  into place when complete. A reader sees the old folder or the new one, never a mix: an existing
  result is swapped out in one ``renameat2(RENAME_EXCHANGE)`` where the kernel has it (Linux), else
  by two renames between which ``NAME`` is briefly absent. A failure (disk full, Ctrl-C, an error)
  removes the staged copy and leaves ``NAME`` as it was; leftovers of a killed writer are swept by
  the next writer of ``NAME``.
* A **completion record**, ``complete.json``, written last into the staged folder: the size and
  SHA-256 of every file in it. :func:`verify_folder` refuses a folder without one (not finished, or
  not ours) or whose files differ from it (truncated, altered, added to), with one line.
* :class:`FolderLock` — an advisory lock (``flock``) on a hidden sibling ``.NAME.lock`` while a
  command writes ``NAME``; a second writer gets :class:`~.errors.FolderLocked` naming the holder's
  pid and command. The kernel drops the lock when its holder dies (even by ``kill -9``), so a lock
  left by a dead process is taken over at once. Locks are re-entrant within one process.

:func:`in_progress` marks a folder that accumulates results (``reproduce --out``) while a command
fills it, and :func:`check_path_names` refuses names the file system cannot hold.

Example (a workspace chunk, written whole or not at all)::

    from fault_tolerance.results import staged_folder, verify_folder

    with staged_folder(out / "chunks" / "0007") as tmp:   # locks out/chunks/0007 too
        np.save(tmp / "values.npy", values)
        (tmp / "chunk.json").write_text(json.dumps(spec))
    verify_folder(out / "chunks" / "0007")                 # later: refuses a torn or altered one
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import hashlib
import json
import os
import shutil
import socket
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from .errors import FolderLocked, IncompleteResult, InvalidInput, OutputError

#: The completion record's file name; written last, lists every other file of the folder.
RECORD = "complete.json"
#: The marker of a folder a command is still filling (see :func:`in_progress`).
IN_PROGRESS = "in_progress.json"
#: ``format`` field of the completion record.
RECORD_FORMAT = "fault_tolerance result folder"
RECORD_VERSION = 1
#: Largest completion record read [bytes] (a record lists a few files).
MAX_RECORD_BYTES = 1 << 20

_STAGE = ".tmp-"
_OLD = ".old-"


# -- writing a folder aside ------------------------------------------------------------------


@contextlib.contextmanager
def staged_folder(
    target: str | Path,
    *,
    replaceable: Iterable[str] = (),
    lock: bool = True,
) -> Iterator[Path]:
    """Yield an empty staging folder; on success record its files and move it to ``target``.

    Args:
        target: The result folder. Its parent is created; ``target`` itself appears only whole.
        replaceable: File names an existing ``target`` may hold and lose (besides the files its
            completion record lists); any other file there makes this refuse with
            :class:`~.errors.InvalidInput` before anything is written, so a user's own files are
            never swept away.
        lock: Hold :class:`FolderLock` on ``target`` while writing (re-entrant).

    Raises:
        FolderLocked: another live process writes ``target``.
        OutputError: the file system refused (full, read-only, permissions); nothing was moved.
    """
    target = Path(target)
    check_path_names(target)
    parent = _make_parent(target)
    holder = FolderLock(target) if lock else contextlib.nullcontext()
    with holder:
        _sweep(target)
        _check_replaceable(target, set(replaceable))
        stage = _new_sibling(target, _STAGE)
        try:
            yield stage
            write_record(stage)
            _commit(stage, target)
        except OSError as err:
            raise _output_error(err, target) from err
        finally:
            if stage.exists():
                shutil.rmtree(stage, ignore_errors=True)
        _fsync(parent)


def check_target(target: str | Path, replaceable: Iterable[str] = ()) -> Path:
    """Refuse early (before a long computation) a ``target`` that :func:`staged_folder` would refuse."""
    target = check_path_names(Path(target))
    _make_parent(target)
    _check_replaceable(target, set(replaceable))
    return target


def write_record(folder: str | Path, **extra) -> dict:
    """Write the completion record of ``folder``: size and SHA-256 of each file (recursively)."""
    folder = Path(folder)
    files = {
        rel: {"bytes": (folder / rel).stat().st_size, "sha256": file_digest(folder / rel)}
        for rel in _files(folder)
        if rel != RECORD
    }
    for rel in files:
        _fsync(folder / rel)
    record = {
        "format": RECORD_FORMAT,
        "version": RECORD_VERSION,
        "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "pid": os.getpid(),
        "command": _command(),
        "files": files,
        **extra,
    }
    _write_synced(folder / RECORD, (json.dumps(record, indent=2) + "\n").encode())
    return record


def read_record(folder: str | Path) -> dict:
    """The completion record of ``folder``, or :class:`~.errors.IncompleteResult` saying why not."""
    folder = Path(folder)
    path = folder / RECORD
    if not folder.is_dir():
        raise IncompleteResult(f"{folder}: no such result folder")
    if not path.is_file():
        why = (
            f"a command is still writing it or was stopped ({IN_PROGRESS} is there)"
            if (folder / IN_PROGRESS).exists()
            else "it was not finished (a command stopped while writing it), or was written by "
            "another tool or an older version"
        )
        raise IncompleteResult(f"{folder}: no completion record ({RECORD}): {why}; write it again")
    if path.stat().st_size > MAX_RECORD_BYTES:
        raise IncompleteResult(f"{path}: larger than {MAX_RECORD_BYTES} bytes; not a record")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise IncompleteResult(f"{path}: not a readable completion record ({err})") from None
    files = record.get("files") if isinstance(record, dict) else None
    ok = (
        isinstance(files, dict)
        and record.get("format") == RECORD_FORMAT
        and all(
            isinstance(v, dict)
            and isinstance(v.get("bytes"), int)
            and isinstance(v.get("sha256"), str)
            for v in files.values()
        )
    )
    if not ok:
        raise IncompleteResult(f"{path}: not a completion record of {RECORD_FORMAT!r}")
    return record


def verify_folder(folder: str | Path, files: Iterable[str] | None = None) -> dict:
    """Check ``folder`` against its completion record; return the record.

    Args:
        folder: A folder written by :func:`staged_folder`.
        files: The files the caller will read: each must be listed and match its size and hash
            (default: every listed file). Files present but not listed are refused too, so nothing
            can be slipped in beside a result.

    Raises:
        IncompleteResult: one line naming the folder and what is missing, added or altered.
    """
    folder = Path(folder)
    record = read_record(folder)
    listed = record["files"]
    present = set(_files(folder)) - {RECORD}
    extra = sorted(present - set(listed))
    if extra:
        raise IncompleteResult(
            f"{folder}: files {extra[:5]} are not in its completion record ({RECORD}); "
            "the folder was altered after it was written"
        )
    names = list(listed) if files is None else list(files)
    for rel in names:
        path = folder / rel
        if rel not in listed:
            raise IncompleteResult(f"{folder}: {rel} is not part of this result ({RECORD})")
        if not path.is_file():
            raise IncompleteResult(f"{folder}: {rel} is missing; the folder was altered")
        size = path.stat().st_size
        if size != listed[rel]["bytes"]:
            raise IncompleteResult(
                f"{path}: {size} bytes, its completion record says {listed[rel]['bytes']}; "
                "the file was truncated or altered"
            )
        if file_digest(path) != listed[rel]["sha256"]:
            raise IncompleteResult(
                f"{path}: its content differs from its completion record (SHA-256); "
                "the file was altered after it was written"
            )
    return record


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes, in hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# -- the lock ----------------------------------------------------------------------------------

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
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as err:
                raise _output_error(err, self.folder) from err
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                info = _read_holder(fd)
                os.close(fd)
                raise FolderLocked(self.folder, info) from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # the holder removed it as we opened it; take the new file
                os.close(fd)
                continue
            info = {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "command": _command(),
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
        fd = os.open(path, os.O_RDONLY)
    except OSError:
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
    with FolderLock(folder):
        marker = folder / IN_PROGRESS
        text = {
            "pid": os.getpid(),
            "command": _command(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            **info,
        }
        try:
            folder.mkdir(parents=True, exist_ok=True)
            _write_synced(folder / f".{IN_PROGRESS}.tmp", (json.dumps(text) + "\n").encode())
            os.replace(folder / f".{IN_PROGRESS}.tmp", marker)
        except OSError as err:
            raise _output_error(err, folder) from err
        yield folder
        marker.unlink(missing_ok=True)


# -- names -----------------------------------------------------------------------------------


def check_path_names(path: str | Path) -> Path:
    """Refuse (``InvalidInput``) a path whose name or length the file system cannot hold."""
    path = Path(path)
    text = os.fsencode(path)
    if b"\x00" in text:
        raise InvalidInput(f"{str(path)!r}: a path cannot contain a NUL character")
    base = _existing_ancestor(path)
    name_max = _pathconf(base, "PC_NAME_MAX", 255)
    path_max = _pathconf(base, "PC_PATH_MAX", 4096)
    # the staging sibling adds ".", ".tmp-" and 8 characters to the last name
    for part in path.parts:
        size = len(os.fsencode(part))
        room = name_max - (16 if part == path.name else 0)
        if size > room:
            raise InvalidInput(
                f"{part[:40]}...: a name of {size} bytes is longer than this file system allows "
                f"({room} bytes for this name); choose a shorter name"
            )
    if len(os.fsencode(os.path.abspath(path))) + 40 > path_max:
        raise InvalidInput(
            f"{str(path)[:60]}...: the path is longer than this file system allows ({path_max} "
            "bytes); choose a shorter one"
        )
    return path


def _existing_ancestor(path: Path) -> Path:
    p = Path(os.path.abspath(path))
    while p != p.parent:
        try:
            if p.exists():
                break
        except OSError:  # e.g. a name too long to stat
            pass
        p = p.parent
    return p


def _pathconf(path: Path, name: str, default: int) -> int:
    try:
        value = os.pathconf(path, name)
    except (OSError, ValueError):
        return default
    return value if value and value > 0 else default


# -- helpers ---------------------------------------------------------------------------------


def _make_parent(target: Path) -> Path:
    parent = target.parent
    if target.exists() and not target.is_dir():
        raise InvalidInput(f"{target}: exists and is not a folder; choose a folder for the output")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise _output_error(err, target) from err
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InvalidInput(f"{parent}: not writable; choose an output folder you can write")
    return parent


def _check_replaceable(target: Path, replaceable: set[str]) -> None:
    if not target.is_dir():
        return
    ours = set(replaceable) | {RECORD, IN_PROGRESS}
    with contextlib.suppress(IncompleteResult):
        ours |= set(read_record(target)["files"])
    foreign = sorted(rel for rel in _files(target) if rel not in ours)
    if foreign:
        raise InvalidInput(
            f"{target}: holds files that are not part of a result ({foreign[:5]}); they would be "
            "replaced: choose a new or empty folder, or move them away"
        )


def _commit(stage: Path, target: Path) -> None:
    """Move the complete ``stage`` to ``target`` (swapping out an existing one)."""
    _fsync(stage)
    if not target.exists():
        os.rename(stage, target)
        return
    if _exchange(stage, target):  # stage now holds the old folder, removed by the caller
        return
    old = _new_sibling(target, _OLD, create=False)
    os.rename(target, old)
    os.rename(stage, target)
    shutil.rmtree(old, ignore_errors=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically with ``renameat2(RENAME_EXCHANGE)``; False where unsupported."""
    fn = _renameat2()
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    if fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


_RENAMEAT2: list = []


def _renameat2():
    if not _RENAMEAT2:
        fn = None
        if sys.platform.startswith("linux"):
            try:
                libc = ctypes.CDLL(None, use_errno=True)
                fn = libc.renameat2
                fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p]
                fn.argtypes += [ctypes.c_uint]
                fn.restype = ctypes.c_int
            except (OSError, AttributeError):
                fn = None
        _RENAMEAT2.append(fn)
    return _RENAMEAT2[0]


def _new_sibling(target: Path, tag: str, create: bool = True) -> Path:
    for _ in range(100):
        path = target.parent / f".{target.name}{tag}{os.urandom(4).hex()}"
        if create:
            try:
                path.mkdir()
                return path
            except FileExistsError:
                continue
        elif not path.exists():
            return path
    raise OutputError(f"{target}: no free name for a staging folder")  # pragma: no cover


def _sweep(target: Path) -> None:
    """Remove staging leftovers of ``target`` from writers that died (we hold its lock)."""
    prefix = f".{target.name}"
    with contextlib.suppress(OSError):
        for p in target.parent.iterdir():
            rest = p.name[len(prefix) :] if p.name.startswith(prefix) else ""
            if rest.startswith((_STAGE, _OLD)) and len(rest) == len(_STAGE) + 8 and p.is_dir():
                shutil.rmtree(p, ignore_errors=True)


def _files(folder: Path) -> list[str]:
    """Relative paths of the regular files (and links) under ``folder``, sorted, '/'-separated."""
    out = []
    for root, dirs, names in os.walk(folder):
        dirs.sort()
        for name in names:
            out.append(os.path.relpath(os.path.join(root, name), folder).replace(os.sep, "/"))
    return sorted(out)


def _write_synced(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _fsync(path: Path) -> None:
    """Flush a file or a folder (its entries) to disk, ignoring file systems that cannot."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _command() -> str:
    argv = [os.path.basename(sys.argv[0] or "python")] + sys.argv[1:]
    text = " ".join(argv)
    return text if len(text) <= 200 else text[:197] + "..."


def _output_error(err: OSError, target: Path) -> Exception:
    """An OSError while writing results as the toolkit's one-line error (not a bug: exit 2)."""
    if isinstance(err, (FolderLocked, IncompleteResult)):
        return err
    reason = {
        errno.ENOSPC: "no space left on the device",
        errno.EDQUOT: "the disk quota is exceeded",
        errno.EROFS: "the file system is read-only",
        errno.EACCES: "permission denied",
        errno.EPERM: "operation not permitted",
        errno.ENAMETOOLONG: "a name is too long for the file system",
    }.get(err.errno or 0, err.strerror or str(err))
    return OutputError(
        f"{target}: could not write the result ({reason}); nothing was written there, an earlier "
        "result is as it was"
    )
