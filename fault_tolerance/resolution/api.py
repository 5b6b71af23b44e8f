"""The public entry points that know the joint limits: :func:`resolve` and :func:`jvj`.

Both are the planner's and the indices' own functions, plus ``bounds=(qd_lo, qd_hi)``: the rate
box of the joint limits (``Arm.rate_bounds(q)``; docs/MATH.md "Joint limits"). Without
``bounds`` they are exactly :func:`fault_tolerance.resolution.resolvers.resolve` and
:func:`fault_tolerance.resolution.indices.jvj` (the paper's formulation).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fault_tolerance.resolution.bounded import resolve_bounded
from fault_tolerance.resolution.indices import jvj as unbounded_jvj
from fault_tolerance.resolution.limits import jvj_under_limits
from fault_tolerance.resolution.resolvers import resolve as unbounded_resolve


def resolve(
    name: str, J: np.ndarray, xdot: np.ndarray, lockable=None, *, bounds=None, **options
) -> np.ndarray:
    """Joint rates from the registered resolver ``name`` (``registry.names()``: lnva, jvja, mda, ...).

    The one ``resolve``: without ``bounds`` the resolver's reference rates
    (:func:`fault_tolerance.resolution.resolvers.resolve`); with ``bounds=(qd_lo, qd_hi)`` its
    bounded variant: the rates minimise the resolver's own objective inside that box, the task
    scaled when it cannot be reached (:func:`fault_tolerance.resolve_bounded` also returns the
    scaling). A resolver registered without a bounded variant raises
    :class:`~fault_tolerance.errors.InvalidInput` when given ``bounds``. Options: the resolver's
    own (its options dataclass; ``weights``, ``response`` for jvja, ``gain``, ``max_step`` for
    mda), and the context ``proj``, ``tolerate``, ``joint_names``, ``arm``, ``q``, ``dJ``; an
    option the resolver does not take raises :class:`~fault_tolerance.errors.InvalidInput`
    naming the ones it takes.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> arm = ft.load_arm("planar_3r")
        >>> q = np.array([0.3, 1.2, 1.0]); J = arm.jacobian(q); xd = np.array([0.1, 0.0])
        >>> qd = ft.resolve("jvja", J, xd, lockable=[1, 2], bounds=arm.rate_bounds(q))
        >>> bool(np.allclose(J @ qd, xd))
        True
    """
    if bounds is None:
        return unbounded_resolve(name, J, xdot, lockable, **options)
    return resolve_bounded(name, J, xdot, lockable, bounds=bounds, **options).qd


def jvj(
    J: np.ndarray,
    xdot: np.ndarray,
    qd: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    per_joint: bool = False,
    joint_names: Sequence[str] = (),
    bounds=None,
):
    """Square-sum joint velocity jump of rates ``qd``, eq. (9)/(10) [(rad/s)²].

    With ``per_joint=True`` the (f, n) array of eq. (1). With ``bounds=(qd_lo, qd_hi)`` the jump
    is measured against the rates each reduced robot takes inside that box (docs/MATH.md
    (L4)-(L5)), and a scenario whose reduced robot cannot keep the task there raises
    :class:`~fault_tolerance.errors.IntolerableUnderLimits`.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> J = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, 0.7]])
        >>> xd = np.array([0.1, 0.0])
        >>> ft.jvj(J, xd, ft.resolve("jvja", J, xd)) <= ft.jvj(J, xd, ft.resolve("lnva", J, xd))
        True
    """
    opts: dict[str, Any] = dict(
        weights=weights, response=response, per_joint=per_joint, joint_names=joint_names
    )
    if bounds is None:
        return unbounded_jvj(J, xdot, qd, lockable, **opts)
    return jvj_under_limits(J, xdot, qd, lockable, bounds=bounds, **opts)
