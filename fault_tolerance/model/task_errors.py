"""Task errors in their own units: position [m] and orientation [rad], never added.

A pose task's error vector mixes metres (rows ``x y z``) and radians (rows ``rx ry rz``); its norm
would add them. :func:`error_norms` gives the two norms separately (docs/MATH.md, "Notation and
units").

Example:
    >>> import numpy as np
    >>> pos, ori = error_norms(("x", "y", "z", "rx", "ry", "rz"), np.array([3e-3, 4e-3, 0, 0, 0, 0.1]))
    >>> round(float(pos), 6), round(float(ori), 6)
    (0.005, 0.1)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: Task rows measured in radians (the rotation vector); the others are in metres.
ANGULAR_ROWS = ("rx", "ry", "rz")


def angular_mask(task: Sequence[str]) -> np.ndarray:
    """Which task rows are angular [rad], shape (m,)."""
    return np.array([r in ANGULAR_ROWS for r in task], dtype=bool)


def error_norms(task: Sequence[str], err: np.ndarray):
    """``(position error [m], orientation error [rad] or None)`` of errors ``err`` (..., m).

    ``None`` when the task has no angular rows. With all three angular rows of
    :meth:`~fault_tolerance.model.arm.Arm.task_error`, the orientation error is the angle of the rotation
    that remains.
    """
    ang = angular_mask(task)
    err = np.asarray(err, dtype=float)
    pos = np.linalg.norm(err[..., ~ang], axis=-1)
    ori = np.linalg.norm(err[..., ang], axis=-1) if ang.any() else None
    return pos, ori
