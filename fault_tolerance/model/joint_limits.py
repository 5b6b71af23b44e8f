"""Joint limits of an arm: position and velocity limits, their defaults, and the rate box (L1).

The rate box is what a joint can do in the next ``h`` seconds: cover at most its distance to a
position limit, never exceed its velocity limit. The bounded resolvers
(:mod:`fault_tolerance.resolution.bounded`) solve inside it. See docs/MATH.md "Joint limits".
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.checks import finite, no_nan

#: Horizon h of the rate box (L1) [s]: a joint covers at most its distance to a limit in h.
RATE_HORIZON = 0.05
#: Velocity limit used where the URDF gives none (0, missing or infinite) [rad/s] (revolute).
DEFAULT_REVOLUTE_SPEED = np.pi
#: The same for prismatic joints [m/s].
DEFAULT_PRISMATIC_SPEED = 1.0
#: Position limits at or beyond this magnitude (Pinocchio's ±1.8e308 of continuous joints) are none.
NO_LIMIT = 1e10


# Eqn. (L1)
def rate_box(q, lower, upper, velocity, horizon: float = RATE_HORIZON):
    """Rate box (L1) at ``q``: ``clip((q_lo − q)/h, −v, v)`` and ``clip((q_hi − q)/h, −v, v)``.

    Position limits of magnitude :data:`NO_LIMIT` or more (continuous joints) and infinite
    velocity limits bound nothing.

    Example:
        >>> lo, hi = rate_box([0.0, 0.99], [-1, -1], [1, 1], [2.0, 2.0], horizon=0.05)
        >>> [round(float(x), 6) for x in hi]
        [2.0, 0.2]
    """
    if not (np.isfinite(horizon) and horizon > 0):
        raise InvalidInput(f"horizon must be finite and > 0 [s], got {horizon}")
    q = finite(q, "q", ndim=1)
    v = np.abs(no_nan(velocity, "velocity", q.shape))
    lower = no_nan(lower, "lower", q.shape)
    upper = no_nan(upper, "upper", q.shape)
    lo_q = np.where(np.abs(lower) < NO_LIMIT, (lower - q) / horizon, -np.inf)
    hi_q = np.where(np.abs(upper) < NO_LIMIT, (upper - q) / horizon, np.inf)
    return np.clip(lo_q, -v, v), np.clip(hi_q, -v, v)


def _prismatic(joint) -> bool:
    short = joint.shortname()
    return short.startswith("JointModelP") and "Planar" not in short


def velocity_limits(arm) -> np.ndarray:
    """The arm's velocity limits [rad/s or m/s], (n,).

    Where the URDF gives none (0, missing or infinite): :data:`DEFAULT_REVOLUTE_SPEED` or
    :data:`DEFAULT_PRISMATIC_SPEED`.
    """
    v = np.abs(arm.velocity_limit)
    model = arm.model
    kinds = [_prismatic(model.joints[j]) for j in range(1, model.njoints) if model.joints[j].nv > 0]
    default = np.where(kinds, DEFAULT_PRISMATIC_SPEED, DEFAULT_REVOLUTE_SPEED)
    return np.where(np.isfinite(v) & (v > 0), v, default)


def arm_rate_box(arm, q, horizon: float = RATE_HORIZON) -> tuple[np.ndarray, np.ndarray]:
    """The box (L1) of ``arm`` at ``q``: its position limits and :func:`velocity_limits`."""
    q = arm.check_q(q)
    return rate_box(q, arm.lower, arm.upper, velocity_limits(arm), horizon)


def wrap_into_limits(arm, q) -> np.ndarray:
    """``q`` with the angles of full-turn joints (limits spanning ≥ 2π) wrapped into their limits."""
    q = np.array(q, dtype=float)
    lo, hi = arm.lower, arm.upper
    full = np.isfinite(hi - lo) & (hi - lo >= 2 * np.pi - 1e-3) & (np.abs(lo) < NO_LIMIT)
    out = full & ((q < lo) | (q > hi))
    q[out] = lo[out] + np.mod(q[out] - lo[out], 2 * np.pi)
    return q


def outside_limits(arm, q, tol: float = 1e-9) -> np.ndarray:
    """Joints of ``q`` (…, n) beyond their position limits by more than ``tol``, bool (…, n)."""
    q = np.asarray(q, dtype=float)
    lo = np.where(np.abs(arm.lower) < NO_LIMIT, arm.lower, -np.inf)
    hi = np.where(np.abs(arm.upper) < NO_LIMIT, arm.upper, np.inf)
    return (q < lo - tol) | (q > hi + tol)
