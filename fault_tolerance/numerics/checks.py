"""Numbers from a caller are checked before use: finite, of the right shape, named in the error.

Every public function that takes arrays passes them through :func:`finite` (or :func:`no_nan`
where ±inf has a meaning, as an absent limit): NaN, ±inf and wrong shapes raise
:class:`~fault_tolerance.errors.InvalidInput` naming the argument, never a NumPy error nor a
finite-looking result computed from NaN.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.errors import InvalidInput


def as_floats(value, name: str, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """``value`` as a float array of ``shape`` (``-1``: any size) or ``ndim``, else InvalidInput."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInput(
            f"{name} must be an array of numbers, got {type(value).__name__}"
        ) from None
    if ndim is not None and a.ndim != ndim:
        raise InvalidInput(f"{name} must have {ndim} dimension(s), got shape {a.shape}")
    if shape is not None and (
        a.ndim != len(shape) or any(s != -1 and s != d for s, d in zip(shape, a.shape, strict=True))
    ):
        want = "(" + ", ".join("any" if s == -1 else str(s) for s in shape)
        want += ",)" if len(shape) == 1 else ")"
        raise InvalidInput(f"{name} must have shape {want}, got {a.shape}")
    return a


def finite(value, name: str, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """``value`` as a finite float array (:func:`as_floats`); NaN or ±inf raise InvalidInput."""
    a = as_floats(value, name, shape, ndim)
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise InvalidInput(f"{name} must be finite; entry {bad} is {a[tuple(bad)]}")
    return a


def no_nan(value, name: str, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """``value`` as a float array without NaN (±inf allowed: e.g. an absent limit)."""
    a = as_floats(value, name, shape, ndim)
    if np.any(np.isnan(a)):
        bad = np.argwhere(np.isnan(a))[0].tolist()
        raise InvalidInput(f"{name} must not contain NaN; entry {bad} is NaN")
    return a
