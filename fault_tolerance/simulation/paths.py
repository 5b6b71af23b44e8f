"""Task paths: desired task position ``x(t)`` and velocity ``ẋ(t)``.

Three kinds: the paper's circles (:class:`CirclePath`), sampled paths from a CSV file
(:class:`SampledPath`, :func:`load_csv`) and Python callables (:class:`FunctionPath`).
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from fault_tolerance.errors import InvalidInput


class TaskPath:
    """A task path of ``m`` coordinates over ``[0, duration]`` seconds.

    Subclasses give ``duration`` and ``x0`` as dataclass fields or as properties.
    """

    if TYPE_CHECKING:  # read-only here: a field or a property may provide them

        @property
        def duration(self) -> float:
            """Length of the path in time [s]."""
            ...

        @property
        def x0(self) -> np.ndarray:
            """Start position."""
            ...

    @property
    def m(self) -> int:
        """Number of task coordinates."""
        return len(self.x0)

    def x(self, t: float) -> np.ndarray:  # pragma: no cover - interface
        """Desired task position at time ``t`` [m or rad], shape (m,)."""
        raise NotImplementedError

    def xdot(self, t: float) -> np.ndarray:  # pragma: no cover - interface
        """Desired task velocity at time ``t`` [m/s or rad/s], shape (m,)."""
        raise NotImplementedError

    def spec(self) -> dict:
        """A JSON-able description (saved with runs)."""
        return {"kind": type(self).__name__, "duration": self.duration, "x0": self.x0.tolist()}


@dataclass(frozen=True)
class CirclePath(TaskPath):
    """The paper's circles: in rows ``(i, j)`` of the task, starting at ``x0``.

    ``ẋ_i = s·Aω sin ωt``, ``ẋ_j = Aω cos ωt`` (``s = ±1``), hence
    ``x_i = x0_i + s·A(1 − cos ωt)``, ``x_j = x0_j + A sin ωt``: a circle of radius ``A`` [m]
    travelled with angular rate ``ω`` [rad/s]. Fig. 2: ``A = 0.1, ω = 2π, s = +1`` gives
    ``ẋ = [0.2π sin 2πt, 0.2π cos 2πt]``.
    """

    x0: np.ndarray
    radius: float
    omega: float
    duration: float
    rows: tuple[int, int] = (0, 1)
    sign: float = 1.0
    name: str = field(default="circle")

    def __post_init__(self) -> None:
        object.__setattr__(self, "x0", np.asarray(self.x0, dtype=float))
        if self.duration <= 0 or not np.isfinite(self.duration):
            raise InvalidInput(f"duration must be > 0, got {self.duration}")
        if self.x0.ndim != 1 or not np.all(np.isfinite(self.x0)):
            raise InvalidInput(f"x0 must be a vector of finite numbers, got {self.x0.tolist()}")
        for key in ("radius", "omega", "sign"):
            if not np.isfinite(getattr(self, key)):
                raise InvalidInput(
                    f"circle {key} must be a finite number, got {getattr(self, key)}"
                )
        i, j = self.rows
        if not (0 <= i < len(self.x0) and 0 <= j < len(self.x0)) or i == j:
            raise InvalidInput(
                f"rows {self.rows} must be two distinct rows of x0 (m={len(self.x0)})"
            )

    def x(self, t: float) -> np.ndarray:
        """Desired position at ``t``."""
        i, j = self.rows
        x = self.x0.copy()
        x[i] += self.sign * self.radius * (1.0 - np.cos(self.omega * t))
        x[j] += self.radius * np.sin(self.omega * t)
        return x

    def xdot(self, t: float) -> np.ndarray:
        """Desired velocity at ``t``."""
        i, j = self.rows
        v = np.zeros_like(self.x0)
        v[i] = self.sign * self.radius * self.omega * np.sin(self.omega * t)
        v[j] = self.radius * self.omega * np.cos(self.omega * t)
        return v

    def sample(self, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Desired positions and velocities at the times ``ts``, shape (K, m) each (vectorised)."""
        ts = np.asarray(ts, dtype=float)
        i, j = self.rows
        X = np.tile(self.x0, (len(ts), 1))
        V = np.zeros_like(X)
        wt = self.omega * ts
        X[:, i] += self.sign * self.radius * (1.0 - np.cos(wt))
        X[:, j] += self.radius * np.sin(wt)
        V[:, i] = self.sign * self.radius * self.omega * np.sin(wt)
        V[:, j] = self.radius * self.omega * np.cos(wt)
        return X, V

    def spec(self) -> dict:
        """JSON-able description."""
        return {
            "kind": "circle",
            "x0": self.x0.tolist(),
            "radius": self.radius,
            "omega": self.omega,
            "duration": self.duration,
            "rows": list(self.rows),
            "sign": self.sign,
            "name": self.name,
        }


@dataclass(frozen=True)
class SampledPath(TaskPath):
    """A path sampled at times ``t`` (strictly increasing), linearly interpolated.

    Velocities are given (``v``) or obtained by differentiation (``np.gradient``, second order).
    """

    t: np.ndarray
    xs: np.ndarray  # shape (K, m)
    v: np.ndarray | None = None
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        xs = np.asarray(self.xs, dtype=float)
        if xs.ndim == 1:
            xs = xs[:, None]
        if t.ndim != 1 or len(t) < 2 or xs.shape[0] != len(t):
            raise InvalidInput(
                f"a sampled path needs >= 2 samples with one time each; got t {t.shape}, x {xs.shape}"
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(xs))):
            raise InvalidInput("a sampled path must have finite times and positions")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InvalidInput(
                f"times must increase strictly; sample {k} has t = {t[k]} after {t[k - 1]}"
            )
        v = np.gradient(xs, t, axis=0) if self.v is None else np.asarray(self.v, dtype=float)
        if v.shape != xs.shape:
            raise InvalidInput(f"velocities have shape {v.shape}, positions {xs.shape}")
        object.__setattr__(self, "t", t - t[0])
        object.__setattr__(self, "xs", xs)
        object.__setattr__(self, "v", v)

    @property
    def x0(self) -> np.ndarray:
        """Start position."""
        return self.xs[0].copy()

    @property
    def duration(self) -> float:
        """Length of the path in time [s]."""
        return float(self.t[-1])

    def _interp(self, data: np.ndarray, t: float) -> np.ndarray:
        return np.array([np.interp(t, self.t, data[:, i]) for i in range(data.shape[1])])

    def x(self, t: float) -> np.ndarray:
        """Interpolated position at ``t``."""
        return self._interp(self.xs, t)

    def xdot(self, t: float) -> np.ndarray:
        """Interpolated velocity at ``t``."""
        return self._interp(cast(np.ndarray, self.v), t)  # set by __post_init__

    def spec(self) -> dict:
        """JSON-able description."""
        return {
            "kind": "sampled",
            "source": self.source,
            "duration": self.duration,
            "x0": self.x0.tolist(),
            "samples": len(self.t),
        }


@dataclass(frozen=True)
class FunctionPath(TaskPath):
    """A path from Python callables ``x(t)`` and optionally ``xdot(t)`` (else central differences)."""

    x_fn: Callable[[float], Sequence[float]]
    duration: float
    xdot_fn: Callable[[float], Sequence[float]] | None = None
    h: float = 1e-6

    def __post_init__(self) -> None:
        if self.duration <= 0 or not np.isfinite(self.duration):
            raise InvalidInput(f"duration must be > 0, got {self.duration}")

    @property
    def x0(self) -> np.ndarray:
        """Start position."""
        return self.x(0.0)

    def x(self, t: float) -> np.ndarray:
        """Position from the callable."""
        return np.asarray(self.x_fn(t), dtype=float)

    def xdot(self, t: float) -> np.ndarray:
        """Velocity from the callable or by central differences."""
        if self.xdot_fn is not None:
            return np.asarray(self.xdot_fn(t), dtype=float)
        return (self.x(t + self.h) - self.x(t - self.h)) / (2 * self.h)


def load_csv(path: str | Path, rows: Sequence[str] | None = None) -> SampledPath:
    """A path from a CSV file with a header ``t, x, y[, z, …]`` and optional ``vx, vy, …`` columns.

    Args:
        path: The CSV file.
        rows: Task coordinate columns to use, in order (default: every column that is neither
            ``t`` nor a ``v…`` velocity column).

    Raises:
        InvalidInput: naming the file, the line and the problem.
    """
    from fault_tolerance.storage.budget import MAX_PATH_FILE_BYTES, check_file_size

    path = Path(path)
    if not path.is_file():
        raise InvalidInput(f"{path}: no such CSV file")
    check_file_size(path, MAX_PATH_FILE_BYTES, "path file (--csv)")
    try:
        header, data = _read_csv_rows(path)
    except UnicodeDecodeError as err:
        raise InvalidInput(
            f"{path}: not UTF-8 text (byte {err.start}); a CSV path must be UTF-8"
        ) from None
    except csv.Error as err:
        raise InvalidInput(f"{path}: not a readable CSV file ({err})") from None
    coords = list(rows) if rows else [h for h in header[1:] if not h.startswith("v")]
    missing = [c for c in coords if c not in header]
    if missing or not coords:
        raise InvalidInput(f"{path}: columns {missing or coords} not found in header {header}")
    vel = [f"v{c}" for c in coords]
    has_v = all(v in header for v in vel)
    arr = np.array([row for _, row in data])
    if len(arr) < 2:
        raise InvalidInput(f"{path}: needs at least 2 data rows, found {len(arr)}")
    idx = [header.index(c) for c in coords]
    v = arr[:, [header.index(c) for c in vel]] if has_v else None
    return SampledPath(arr[:, 0], arr[:, idx], v, source=str(path))


def _read_csv_rows(path: Path) -> tuple[list[str], list[tuple[int, list[float]]]]:
    """Header and numeric rows ``(line number, values)`` of a path CSV, each row checked."""
    with path.open(newline="", encoding="utf-8-sig") as fh:  # -sig: a spreadsheet's BOM is fine
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InvalidInput(
                f"{path}: the file is empty; expected a header 't,x,y,...'"
            ) from None
        if not header or header[0] != "t":
            raise InvalidInput(f"{path}: the first column must be 't', the header is {header}")
        twice = sorted({h for h in header if header.count(h) > 1})
        if twice:
            raise InvalidInput(f"{path}: columns {twice} appear twice in the header {header}")
        if len(header) > 64:
            raise InvalidInput(f"{path}: {len(header)} columns; a path has at most 64")
        from fault_tolerance.storage.budget import MAX_RUN_SAMPLES

        data: list[tuple[int, list[float]]] = []
        for lineno, row in enumerate(reader, start=2):
            if len(data) > MAX_RUN_SAMPLES:
                raise InvalidInput(
                    f"{path}: more than {MAX_RUN_SAMPLES:,} rows; a path file may have at most that"
                )
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise InvalidInput(
                    f"{path}:{lineno}: {len(row)} fields, the header has {len(header)}"
                )
            try:
                values = [float(c) for c in row]
            except ValueError:
                raise InvalidInput(f"{path}:{lineno}: a field is not a number: {row}") from None
            if not all(np.isfinite(values)):
                raise InvalidInput(f"{path}:{lineno}: fields must be finite numbers, got {row}")
            if data and values[0] <= data[-1][1][0]:
                raise InvalidInput(
                    f"{path}:{lineno}: t = {values[0]} does not increase (line "
                    f"{data[-1][0]} has t = {data[-1][1][0]}); times must increase strictly"
                )
            data.append((lineno, values))
    return header, data
