"""Reading a saved run as untrusted input: sizes, shapes, types and metadata checked before use.

:func:`read_run_file` is what :meth:`~.run.Run.load` calls after the folder's completion record
(:mod:`~.results`) has been checked. It reads the zip directory and the ``.npy`` headers first
(:func:`~.budget.npz_members`: nothing is allocated from a forged size), checks that every array
has the shape the others imply (K samples, n joints, m task rows, f scenarios), that times are
finite and increasing, and that ``meta`` is a JSON object whose fields have the types the toolkit
reads. Any problem is one line of :class:`~.errors.InvalidInput`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.budget import MAX_RUN_SAMPLES, npz_members

#: Shape of each array of a run, in the symbols K (samples), n, m, f.
SHAPES = {
    "t": ("K",),
    "q": ("K", "n"),
    "qd": ("K", "n"),
    "x": ("K", "m"),
    "x_des": ("K", "m"),
    "error": ("K",),
    "jvj": ("K",),
    "jvj_parts": ("K", "f"),
    "rcn": ("K", "f"),
    "K": ("K",),
    "sigma_min": ("K",),
    "flags": ("K",),
    "qd_cmd": ("K", "n"),
    "orientation_error": ("K",),  # tasks with angular rows [rad]
    "tau": ("K", "n"),  # dynamics runs: applied joint torques [N·m]
    "tau_cmd": ("K", "n"),  # dynamics runs: commanded torques before saturation [N·m]
}
#: Members that are JSON text (0-d string arrays).
TEXT_MEMBERS = ("meta", "arm")

#: Types of the ``meta`` fields the toolkit reads (others are kept as they are).
META_TYPES: dict[str, type | tuple[type, ...]] = {
    "robot": str,
    "algorithm": str,
    "tip": str,
    "task": list,
    "joint_names": list,
    "dt": (int, float),
    "duration": (int, float),
    "lock": (dict, type(None)),
}


def read_run_file(path: str | Path, required: tuple[str, ...]) -> tuple[dict, dict, dict | None]:
    """``(arrays, meta, arm record or None)`` of a ``run.npz``, every check done before use."""
    path = Path(path)
    members = npz_members(path)
    unknown = sorted(set(members) - set(SHAPES) - set(TEXT_MEMBERS))
    if unknown:
        raise InvalidInput(f"{path}: unknown arrays {unknown[:5]}; not a run of this toolkit")
    missing = [k for k in (*required, "meta") if k not in members]
    if missing:
        raise InvalidInput(f"{path}: run file lacks arrays {missing}")
    _check_shapes(path, members)
    for key in TEXT_MEMBERS:
        if key in members and (members[key][0] != () or members[key][1].kind != "U"):
            raise InvalidInput(f"{path}: {key!r} must be one JSON text, got {members[key]}")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in members if k not in TEXT_MEMBERS}
            texts = {k: str(z[k]) for k in TEXT_MEMBERS if k in members}
    except (OSError, ValueError, KeyError, EOFError) as err:  # zip CRC, truncated data
        raise InvalidInput(f"{path}: not a readable run file ({_short(err)})") from None
    meta = _json(path, "meta", texts["meta"])
    if not isinstance(meta, dict):
        raise InvalidInput(f"{path}: 'meta' must be a JSON object, got {type(meta).__name__}")
    check_meta(meta, path, arrays)
    arm = _json(path, "arm", texts["arm"]) if "arm" in texts else None
    _check_values(path, arrays)
    return arrays, meta, arm


def _check_shapes(path: Path, members: dict) -> None:
    sizes: dict[str, int] = {}
    for name, (shape, dtype) in members.items():
        if name in TEXT_MEMBERS:
            continue
        want = SHAPES[name]
        if dtype.kind not in "biuf":
            raise InvalidInput(f"{path}: array {name!r} has dtype {dtype}; it must hold numbers")
        if len(shape) != len(want):
            raise InvalidInput(
                f"{path}: array {name!r} has shape {shape}; it must be ({', '.join(want)})"
            )
        for sym, size in zip(want, shape, strict=True):
            if sizes.setdefault(sym, size) != size:
                raise InvalidInput(
                    f"{path}: array {name!r} has shape {shape}, but other arrays have "
                    f"{sym} = {sizes[sym]}; the arrays of a run must agree (a ragged file)"
                )
    if not 1 <= sizes.get("K", 0) <= MAX_RUN_SAMPLES + 1:
        raise InvalidInput(
            f"{path}: {sizes.get('K', 0)} samples; a run has 1 to {MAX_RUN_SAMPLES + 1:,}"
        )
    if sizes.get("n", 1) < 1 or sizes.get("m", 1) < 1:
        raise InvalidInput(f"{path}: a run needs at least one joint and one task row")


def _check_values(path: Path, arrays: dict) -> None:
    t = arrays["t"]
    if not np.all(np.isfinite(t)) or (len(t) > 1 and np.any(np.diff(t) <= 0)):
        raise InvalidInput(f"{path}: the times t must be finite and strictly increasing")
    if not np.all(np.isfinite(arrays["q"])):
        raise InvalidInput(f"{path}: the joint positions q must be finite")


def check_meta(meta: dict, path, arrays: dict | None = None) -> dict:
    """``meta`` if the fields the toolkit reads have their types, else InvalidInput naming one."""
    for key, kind in META_TYPES.items():
        if key in meta and (not isinstance(meta[key], kind) or isinstance(meta[key], bool)):
            raise InvalidInput(
                f"{path}: meta field {key!r} has type {type(meta[key]).__name__}; "
                f"expected {_names(kind)}"
            )
    for key in ("task", "joint_names"):
        if key in meta and not all(isinstance(v, str) for v in meta[key]):
            raise InvalidInput(f"{path}: meta field {key!r} must be a list of names")
    n = arrays["q"].shape[1] if arrays else None
    if n is not None and "joint_names" in meta and len(meta["joint_names"]) != n:
        raise InvalidInput(
            f"{path}: meta names {len(meta['joint_names'])} joints, the arrays have {n}"
        )
    lock = meta.get("lock")
    if lock:
        time, index = lock.get("time"), lock.get("index")
        if not (
            isinstance(time, (int, float)) and not isinstance(time, bool) and math.isfinite(time)
        ):
            raise InvalidInput(f"{path}: the lock time must be a finite number, got {time!r}")
        if not isinstance(lock.get("joint"), str):
            raise InvalidInput(f"{path}: the locked joint must be a name")
        if index is not None and not (
            isinstance(index, int) and not isinstance(index, bool) and 0 <= index < (n or 1 << 30)
        ):
            raise InvalidInput(f"{path}: the locked joint's index {index!r} is not a joint")
        jump = lock.get("jump")
        if jump is not None and not (isinstance(jump, (int, float)) and not isinstance(jump, bool)):
            raise InvalidInput(f"{path}: the lock jump must be a number, got {jump!r}")
    return meta


def _json(path: Path, key: str, text: str):
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as err:
        raise InvalidInput(f"{path}: {key!r} is not JSON ({_short(err)})") from None


def _names(kind) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join("null" if k is type(None) else k.__name__ for k in kinds)


def _short(err: Exception) -> str:
    return " ".join(str(err).split())[:160]
