"""Bounded work: estimate what a command will allocate and refuse what would not fit, up front.

A run of ``duration / dt`` samples keeps a dozen arrays of that length; a replay records
``span / speed · fps`` frames; a saved run declares its arrays' shapes in its ``.npy`` headers. Each
is estimated *before* anything is allocated and refused with :class:`~.errors.InvalidInput` naming
the option and the limit, instead of ending in a ``MemoryError``, an OOM kill or hours of work.

The limits (module constants) are documented in README's "Errors and limits":

* :data:`MAX_RUN_SAMPLES` samples per run (``--duration / --dt``), and the run's arrays within
  :func:`memory_budget` (the smaller of :data:`MAX_RUN_BYTES` and half the memory available now);
* :data:`MAX_REPLAY_FRAMES` frames per replay (``run length / --speed · fps``);
* :data:`MAX_RUN_FILE_BYTES` bytes of arrays in a saved run, checked from the zip directory and
  each array's header, so a forged header cannot make NumPy allocate what the file does not hold;
* :data:`MAX_PATH_FILE_BYTES` bytes and :data:`MAX_RUN_SAMPLES` rows of a path file.

Example:
    >>> run_samples(1e-3, 2.0)
    2001
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput

#: Most samples one run may have (1000 s at the paper's dt = 1 ms).
MAX_RUN_SAMPLES = 1_000_000
#: Most bytes the arrays of one run may take in memory (further capped by the memory available).
MAX_RUN_BYTES = 1 << 30
#: Most frames of one replay (10 minutes at 50 frames per second).
MAX_REPLAY_FRAMES = 30_000
#: Most bytes of (decompressed) arrays in a saved run file.
MAX_RUN_FILE_BYTES = 1 << 30
#: Largest task-path file (CSV) read [bytes].
MAX_PATH_FILE_BYTES = 100 * 1024 * 1024

#: float64 arrays a run keeps per sample, as multiples of (1, n, m, f): t, error, jvj, K,
#: sigma_min, flags; q, qd, qd_cmd; x, x_des; jvj_parts, rcn.
_PER_SAMPLE = (6, 3, 2, 2)


def run_samples(dt: float, duration: float) -> int:
    """Samples of a run of ``duration`` [s] at step ``dt`` [s], or InvalidInput past the limit."""
    if not (math.isfinite(dt) and dt > 0):
        raise InvalidInput(f"dt must be a finite number > 0 [s] (--dt), got {dt}")
    if not (math.isfinite(duration) and duration > 0):
        raise InvalidInput(f"duration must be a finite number > 0 [s] (--duration), got {duration}")
    steps = duration / dt
    if not steps < MAX_RUN_SAMPLES:  # also catches inf
        raise InvalidInput(
            f"dt = {dt:g} s over duration = {duration:g} s is {steps:.3g} samples; at most "
            f"{MAX_RUN_SAMPLES:,} are allowed per run: raise --dt or shorten --duration"
        )
    return int(round(steps)) + 1


def run_bytes(samples: int, n: int, m: int, f: int) -> int:
    """Bytes the arrays of a run of ``samples`` take (n joints, m task rows, f scenarios)."""
    a, b, c, d = _PER_SAMPLE
    return 8 * samples * (a + b * n + c * m + d * f)


def memory_budget() -> int:
    """Bytes a command may allocate for results: ``MAX_RUN_BYTES`` or half the available memory."""
    return min(MAX_RUN_BYTES, available_memory() // 2)


def available_memory() -> int:
    """Memory available now [bytes] (``MemAvailable`` of /proc/meminfo; large if unknown)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 1 << 40


def check_run(dt: float, duration: float, n: int, m: int, f: int, runs: int = 1) -> int:
    """Samples per run, after checking ``runs`` runs fit :func:`memory_budget`; else InvalidInput."""
    samples = run_samples(dt, duration)
    need = runs * run_bytes(samples, n, m, f)
    budget = memory_budget()
    if need > budget:
        raise InvalidInput(
            f"{runs} run(s) of {samples:,} samples with {n} joints and {f} scenarios need "
            f"{need / 2**20:,.0f} MiB; at most {budget / 2**20:,.0f} MiB are allowed: raise --dt, "
            "shorten --duration or run fewer algorithms at once"
        )
    return samples


def check_frames(span: float, speed: float, fps: float) -> int:
    """Frames of a replay of ``span`` run seconds, or InvalidInput naming --speed past the limit."""
    frames = span / speed * fps
    if not frames <= MAX_REPLAY_FRAMES:
        raise InvalidInput(
            f"replaying {span:g} s at --speed {speed:g} and {fps:g} fps is {frames:.3g} frames; "
            f"at most {MAX_REPLAY_FRAMES:,} are allowed: raise --speed (at least "
            f"{span * fps / MAX_REPLAY_FRAMES:.3g} here)"
        )
    return max(1, int(math.ceil(frames - 1e-9)))


def check_file_size(path: str | Path, limit: int, what: str) -> int:
    """Size of ``path`` [bytes], or InvalidInput if it is larger than ``limit``."""
    size = Path(path).stat().st_size
    if size > limit:
        raise InvalidInput(f"{path}: {size:,} bytes; a {what} may have at most {limit:,}")
    return size


def npz_members(path: str | Path, limit: int | None = None) -> dict[str, tuple]:
    """``{name: (shape, dtype)}`` of an ``.npz`` file's arrays, checked before any is loaded.

    Each member must be a stored or deflated ``.npy`` whose header (read, not the data) declares a
    plain numeric, boolean or string dtype and a shape whose byte size matches the member's
    decompressed size in the zip directory; the sizes must add up to at most ``limit``.

    Raises:
        InvalidInput: naming the file and the member.
    """
    path = Path(path)
    limit = MAX_RUN_FILE_BYTES if limit is None else limit
    total = 0
    out: dict[str, tuple] = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                name = info.filename
                if not name.endswith(".npy") or "/" in name or info.is_dir():
                    raise InvalidInput(f"{path}: member {name[:60]!r} is not an array of a run")
                if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                    raise InvalidInput(f"{path}: member {name!r} uses an unsupported compression")
                total += info.file_size
                if total > limit:
                    raise InvalidInput(
                        f"{path}: its arrays hold more than {limit:,} bytes decompressed; "
                        "the limit for a saved run"
                    )
                with zf.open(info) as fh:
                    shape, dtype, header = _npy_header(fh, path, name)
                count = math.prod(shape)
                if header + count * dtype.itemsize != info.file_size:
                    raise InvalidInput(
                        f"{path}: array {name[:-4]!r} declares shape {shape} of {dtype}, which "
                        f"does not match its {info.file_size} bytes; the file is truncated or forged"
                    )
                out[name[:-4]] = (shape, dtype)
    except zipfile.BadZipFile as err:
        raise InvalidInput(f"{path}: not a readable run file ({err})") from None
    except (OSError, EOFError) as err:
        raise InvalidInput(f"{path}: not a readable run file ({err})") from None
    return out


def _npy_header(fh, path: Path, name: str):
    from numpy.lib import format as npformat

    try:
        major, _ = npformat.read_magic(fh)
        if major == 1:
            shape, fortran, dtype = npformat.read_array_header_1_0(fh)
        elif major in (2, 3):
            shape, fortran, dtype = npformat.read_array_header_2_0(fh)
        else:
            raise ValueError(f"npy format version {major}")
        header = fh.tell()
    except (ValueError, SyntaxError, TypeError) as err:
        raise InvalidInput(f"{path}: array {name!r} has no valid .npy header ({err})") from None
    if dtype.hasobject or dtype.kind not in "biufcUS" or dtype.fields is not None:
        raise InvalidInput(f"{path}: array {name!r} has dtype {dtype}; a run holds numbers only")
    if not all(isinstance(s, int) and s >= 0 for s in shape) or len(shape) > 4:
        raise InvalidInput(f"{path}: array {name!r} has shape {shape}; not an array of a run")
    return tuple(shape), np.dtype(dtype), header


# -- sweeps: workspace and design sizes, refused before any work -----------------------------

#: Most chunks one sweep may have (``--chunks``, or the sampled method's chunk count).
MAX_CHUNKS = 100_000
#: Most configurations of a sampled workspace, or joint-3 values of a planar-3R self-motion.
MAX_SAMPLES = 10_000_000
#: Most lock angles per joint of a workspace (``--theta-samples``).
MAX_THETA_SAMPLES = 100_000
#: Most quasi-random candidates of a design search (``--candidates``).
MAX_CANDIDATES = 100_000
#: Most pattern-search rounds (``--rounds``): each halves the step, and after 60 the step is
#: below the resolution of a double on the search box.
MAX_ROUNDS = 60
#: Most joints of an arm a sweep accepts.
MAX_SWEEP_JOINTS = 100
#: Bytes one grid point of a workspace map takes in memory (masks, two float maps, the layout's
#: integer keys and indices), besides one byte per lockable joint.
_POINT_BYTES = 64


def check_count(value, name: str, lo: int, hi: int) -> int:
    """``value`` as an integer in ``[lo, hi]``, or InvalidInput naming ``name`` and the range."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and value == int(value):
        ok, value = True, int(value)
    if not ok or not lo <= value <= hi:
        raise InvalidInput(f"{name} must be an integer from {lo:,} to {hi:,}, got {value!r}")
    return int(value)


def grid_bytes(grid: int, dims: int, lockable: int) -> int:
    """Bytes the maps of a workspace on ``grid`` points per axis in ``dims`` axes take."""
    return grid**dims * (_POINT_BYTES + lockable)


def check_grid(grid, dims: int, lockable: int, name: str = "grid (--grid)") -> int:
    """Points per axis of a workspace map, after checking its maps fit :func:`memory_budget`."""
    grid = check_count(grid, name, 2, 10**9)
    need, budget = grid_bytes(grid, dims, lockable), memory_budget()
    if need > budget:
        most = int((budget / (_POINT_BYTES + lockable)) ** (1.0 / dims))
        raise InvalidInput(
            f"{name} = {grid:,} is {grid:,}^{dims} points, whose maps need {need / 2**20:,.0f} "
            f"MiB; at most {budget / 2**20:,.0f} MiB are allowed (a grid of at most {most:,})"
        )
    return grid


def check_workspace(spec: dict, n_chunks: int) -> None:
    """Refuse a workspace spec whose sizes exceed the limits above, before any chunk runs."""
    f = len(spec["lockable"])
    check_count(len(spec["robot"]["joints"]), "the arm's joints", 1, MAX_SWEEP_JOINTS)
    check_grid(spec["grid"], len(spec["center"]), f)
    check_count(spec["samples"], "samples (--samples)", 1, MAX_SAMPLES)
    check_count(spec["theta_samples"], "theta_samples (--theta-samples)", 2, MAX_THETA_SAMPLES)
    what = "chunks (--chunks)" if spec.get("chunks") else "chunks of the sampled method"
    check_count(n_chunks, what, 1, MAX_CHUNKS)


def check_design(candidates, rounds, grid) -> tuple[int, int, int]:
    """``(candidates, rounds, grid)`` of a design search, checked against the limits above."""
    return (
        check_count(candidates, "candidates (--candidates)", 1, MAX_CANDIDATES),
        check_count(rounds, "rounds (--rounds)", 0, MAX_ROUNDS),
        check_grid(grid, 2, 3),
    )
