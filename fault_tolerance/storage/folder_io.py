"""File-system helpers of result folders: names it can hold, synced writes, one-line errors.

The lowest layer under :mod:`.results` and :mod:`.folder_lock`: :func:`check_path_names` refuses a
path whose names the file system cannot hold (before a long computation), :func:`write_synced`
and :func:`fsync` put bytes and folder entries on disk, and :func:`output_error` turns an
``OSError`` into the toolkit's one-line :class:`~.errors.OutputError`.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import sys
from pathlib import Path

from fault_tolerance.errors import FolderLocked, IncompleteResult, InvalidInput, OutputError


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


def files_below(folder: Path) -> list[str]:
    """Relative paths of the regular files (and links) under ``folder``, sorted, '/'-separated."""
    out = []
    for root, dirs, names in os.walk(folder):
        dirs.sort()
        for name in names:
            out.append(os.path.relpath(os.path.join(root, name), folder).replace(os.sep, "/"))
    return sorted(out)


#: Flags of every file a writer creates: a new regular file, never through a symbolic link.
NEW_FILE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
#: Flags of every file a reader of untrusted folders opens: no link followed, no FIFO waited on.
READ_FILE = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)


def refuse_link(path: str | Path, *, folder: bool = False) -> Path:
    """Refuse (``OutputError``) a symbolic link or special file where a writer will write.

    ``path`` may be absent; if it exists it must be a regular file (``folder=False``) or a real
    folder (``folder=True``), checked with ``lstat`` so a link is never followed.
    """
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as err:
        raise output_error(err, path) from err
    if stat.S_ISLNK(st.st_mode):
        raise OutputError(
            f"{path}: is a symbolic link; a writer never follows links (its target would be "
            "overwritten): remove the link or choose another output folder"
        )
    ok = stat.S_ISDIR(st.st_mode) if folder else stat.S_ISREG(st.st_mode)
    if not ok:
        kind = "a folder" if folder else "a regular file"
        raise OutputError(
            f"{path}: exists and is not {kind} ({_kind(st.st_mode)}); remove it or choose "
            "another output folder"
        )
    return path


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return name
    return "a regular file" if stat.S_ISREG(mode) else "a special file"


def is_regular(path: str | Path) -> bool:
    """True if ``path`` is a regular file itself (not a link to one, not a FIFO or device)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def open_regular(path: str | Path) -> int:
    """A read-only descriptor of the regular file ``path``, never through a link nor a FIFO.

    Raises:
        OSError: ``path`` is missing, a link (``ELOOP``) or not a regular file (``EINVAL``).
    """
    fd = os.open(path, READ_FILE)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    return fd


def write_synced(path: Path, data: bytes) -> None:
    """Write ``data`` to the new file ``path`` (never through a link) and flush it to disk.

    A leftover regular file or link at ``path`` is removed first (the link, not its target).
    """
    refuse_folder = os.path.isdir(path) and not os.path.islink(path)
    if refuse_folder:
        raise OutputError(f"{path}: exists and is a folder; remove it or choose another folder")
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)
    fd = os.open(path, NEW_FILE, 0o644)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def fsync(path: Path) -> None:
    """Flush a file or a folder (its entries) to disk, ignoring file systems that cannot."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def command_line() -> str:
    """This process's command line, shortened to 200 characters (for records and locks)."""
    argv = [os.path.basename(sys.argv[0] or "python")] + sys.argv[1:]
    text = " ".join(argv)
    return text if len(text) <= 200 else text[:197] + "..."


def output_error(err: OSError, target: Path) -> Exception:
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
