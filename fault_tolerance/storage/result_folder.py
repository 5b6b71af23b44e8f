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
fills it, and :func:`check_path_names` refuses names the file system cannot hold. The lock and the
marker live in :mod:`.folder_lock`, the name checks and synced writes in :mod:`.folder_io`; all are
importable from here.

Example (a workspace chunk, written whole or not at all)::

    from fault_tolerance.storage.result_folder import staged_folder, verify_folder

    with staged_folder(out / "chunks" / "0007") as tmp:   # locks out/chunks/0007 too
        np.save(tmp / "values.npy", values)
        (tmp / "chunk.json").write_text(json.dumps(spec))
    verify_folder(out / "chunks" / "0007")                 # later: refuses a torn or altered one
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fnmatch
import hashlib
import json
import os
import shutil
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from fault_tolerance.errors import IncompleteResult, InvalidInput, OutputError
from fault_tolerance.storage.folder_io import (
    check_path_names,
    command_line,
    files_below,
    fsync,
    is_regular,
    open_regular,
    output_error,
    refuse_link,
    write_synced,
)
from fault_tolerance.storage.folder_lock import (
    IN_PROGRESS,
    FolderLock,
)

__all__ = [
    "RECORD",
    "check_target",
    "created_folders",
    "file_digest",
    "read_record",
    "staged_folder",
    "verify_folder",
    "write_record",
]

#: The completion record's file name; written last, lists every other file of the folder.
RECORD = "complete.json"
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
    aside: Iterable[str] = (),
) -> Iterator[Path]:
    """Yield an empty staging folder; on success record its files and move it to ``target``.

    Args:
        target: The result folder. Its parent is created; ``target`` itself appears only whole.
        replaceable: File names an existing ``target`` may hold and lose (besides the files its
            completion record lists); any other file there makes this refuse with
            :class:`~.errors.InvalidInput` before anything is written, so a user's own files are
            never swept away.
        lock: Hold :class:`FolderLock` on ``target`` while writing (re-entrant).
        aside: Glob patterns (``"chunks-*"``) of top-level entries of an existing ``target`` that
            live beside the result rather than in it (a sweep's finished chunks): their regular
            files are carried into the new folder by hard links (copies where the file system
            has none), left out of the completion record, and ignored by :func:`verify_folder`.

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
        aside = list(aside)
        _check_replaceable(target, set(replaceable) | {f"{a}/*" for a in aside})
        stage = _new_sibling(target, _STAGE)
        try:
            yield stage
            write_record(stage, aside=aside)
            _carry(target, stage, aside)
            _commit(stage, target)
        except OSError as err:
            raise output_error(err, target) from err
        finally:
            if stage.exists():
                shutil.rmtree(stage, ignore_errors=True)
        fsync(parent)


def check_target(target: str | Path, replaceable: Iterable[str] = ()) -> Path:
    """Refuse early (before a long computation) a ``target`` that :func:`staged_folder` would refuse."""
    target = check_path_names(Path(target))
    _make_parent(target)
    _check_replaceable(target, set(replaceable))
    return target


@contextlib.contextmanager
def created_folders(path: str | Path) -> Iterator[Path]:
    """Remove, when the block fails, the folders up to ``path`` it created and left empty.

    A failed command leaves no empty ``--out`` (nor empty parents of it) behind; a folder that
    holds anything (finished chunks, a user's files) is kept.
    """
    path = Path(os.path.abspath(path))
    first = None
    p = path
    while not os.path.lexists(p) and p != p.parent:
        first, p = p, p.parent
    try:
        yield path
    except BaseException:
        if first is not None:
            p = path
            while True:
                with contextlib.suppress(OSError):
                    os.rmdir(p)  # only if empty
                if p == first or p == p.parent:
                    break
                p = p.parent
        raise


def write_record(folder: str | Path, *, aside: Iterable[str] = (), **extra) -> dict:
    """Write the completion record of ``folder``: size and SHA-256 of each file (recursively).

    Files under the top-level entries matching ``aside`` (glob patterns) are not part of the
    result; the patterns are recorded so that :func:`verify_folder` ignores them too.
    """
    folder = Path(folder)
    aside = list(aside)
    files = {
        rel: {"bytes": os.lstat(folder / rel).st_size, "sha256": file_digest(folder / rel)}
        for rel in files_below(folder)
        if rel != RECORD and not _is_aside(rel, aside)
    }
    if aside:
        extra["aside"] = aside
    for rel in files:
        fsync(folder / rel)
    record = {
        "format": RECORD_FORMAT,
        "version": RECORD_VERSION,
        "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "pid": os.getpid(),
        "command": command_line(),
        "files": files,
        **extra,
    }
    write_synced(folder / RECORD, (json.dumps(record, indent=2) + "\n").encode())
    return record


def read_record(folder: str | Path) -> dict:
    """The completion record of ``folder``, or :class:`~.errors.IncompleteResult` saying why not."""
    folder = Path(folder)
    path = folder / RECORD
    if not folder.is_dir():
        raise IncompleteResult(f"{folder}: no such result folder")
    if os.path.lexists(path) and not is_regular(path):
        raise IncompleteResult(f"{path}: not a regular file (a link or special file); not a record")
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
        fd = open_regular(path)
        with os.fdopen(fd, "rb") as fh:
            record = json.loads(fh.read(MAX_RECORD_BYTES).decode("utf-8"))
    except OSError as err:
        raise IncompleteResult(f"{path}: not a readable completion record ({err})") from None
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
    found = record.get("aside")
    aside: list[str] = [str(a) for a in found] if isinstance(found, list) else []
    present = {r for r in files_below(folder) if not _is_aside(r, aside)} - {RECORD}
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
        if not is_regular(path):
            raise IncompleteResult(
                f"{folder}: {rel} is missing or not a regular file; the folder was altered"
            )
        size = os.lstat(path).st_size
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
    """SHA-256 of a regular file's bytes, in hex (a link or FIFO raises ``OSError``)."""
    h = hashlib.sha256()
    with os.fdopen(open_regular(path), "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# -- helpers ---------------------------------------------------------------------------------


def _is_aside(rel: str, aside: Iterable[str]) -> bool:
    top = rel.split("/", 1)[0]
    return "/" in rel and any(fnmatch.fnmatchcase(top, a) for a in aside)


def _carry(target: Path, stage: Path, aside: list[str]) -> None:
    """Hard-link the regular files of ``target``'s aside entries into ``stage`` (module doc)."""
    if not aside or not target.is_dir():
        return
    for rel in files_below(target):
        if not _is_aside(rel, aside) or not is_regular(target / rel):
            continue  # a link or FIFO among the chunks is not carried (it would be recomputed)
        dst = stage / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        if dst.exists():
            continue
        try:
            os.link(target / rel, dst, follow_symlinks=False)
        except OSError:
            shutil.copyfile(target / rel, dst, follow_symlinks=False)


def _make_parent(target: Path) -> Path:
    if os.path.islink(target):
        refuse_link(target, folder=True)
    parent = target.parent
    if target.exists() and not target.is_dir():
        raise InvalidInput(f"{target}: exists and is not a folder; choose a folder for the output")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise output_error(err, target) from err
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InvalidInput(f"{parent}: not writable; choose an output folder you can write")
    return parent


def _check_replaceable(target: Path, replaceable: set[str]) -> None:
    if not target.is_dir():
        return
    ours = set(replaceable) | {RECORD, IN_PROGRESS}
    with contextlib.suppress(IncompleteResult):
        ours |= set(read_record(target)["files"])
    refuse_link(target, folder=True)
    for rel in files_below(target):  # a link or FIFO where a result's file was: refuse, name it
        if not any(fnmatch.fnmatchcase(rel, p) for p in replaceable if "*" in p):
            refuse_link(target / rel)
    foreign = sorted(
        rel
        for rel in files_below(target)
        if rel not in ours and not any(fnmatch.fnmatchcase(rel, p) for p in replaceable)
    )
    if foreign:
        raise InvalidInput(
            f"{target}: holds files that are not part of a result ({foreign[:5]}); they would be "
            "replaced: choose a new or empty folder, or move them away"
        )


def _commit(stage: Path, target: Path) -> None:
    """Move the complete ``stage`` to ``target`` (swapping out an existing one)."""
    fsync(stage)
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
