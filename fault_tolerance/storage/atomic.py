"""Files that are whole or absent: atomic writes, output folders, JSON of NumPy values.

A reader never sees a half-written file, and an interrupted write leaves the old file intact.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.folder_io import refuse_link


def write_atomic(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` via a temporary file in the same folder and ``os.replace``.

    A reader never sees a half-written file, and an interrupted write leaves the old file intact.
    A symbolic link or special file at ``path`` is refused (``OutputError``), never followed.
    """
    path = refuse_link(Path(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    raw = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def output_folder(path: str | Path) -> Path:
    """``path`` as a folder that exists and can be written to, or :class:`InvalidInput` saying why."""
    path = refuse_link(Path(path), folder=True)
    if path.exists() and not path.is_dir():
        raise InvalidInput(f"{path}: exists and is not a folder; choose a folder for the output")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InvalidInput(f"{path}: cannot create the output folder ({err.strerror})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InvalidInput(f"{path}: the output folder is not writable")
    return path


def to_json(obj) -> str:
    """``obj`` as indented JSON text (NumPy arrays and scalars as lists and numbers)."""
    return json.dumps(obj, indent=2, default=_to_builtin) + "\n"


def _to_builtin(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")
