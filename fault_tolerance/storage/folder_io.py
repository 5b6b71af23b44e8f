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


def write_synced(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` and flush it to disk before returning."""
    with open(path, "wb") as fh:
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
