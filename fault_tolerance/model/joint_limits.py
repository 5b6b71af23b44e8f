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


# -- units of a start: radians on turning joints, metres on sliding ones ------------------------

#: A turning joint's start beyond this magnitude [rad] (a turn and 1 %) and outside its limits is
#: refused: no start needs it, and it is what degrees read as radians look like (docs/units.md).
TURN_LIMIT = 2 * np.pi * 1.01
#: The hint of values given on the command line that look like degrees.
DEGREES_OPTION_HINT = "looks like degrees: pass --deg"
#: The hint of a start that looks like degrees (CLI and Python).
DEGREES_HINT = f"{DEGREES_OPTION_HINT} (in Python, np.deg2rad(q0))"


def _linear(joint) -> bool:
    """True for a joint whose coordinates are lengths [m] (prismatic, translation)."""
    return _prismatic(joint) or joint.shortname() == "JointModelTranslation"


def angular_columns(arm) -> np.ndarray:
    """Which entries of ``q`` (columns of J) are angles [rad]: revolute, continuous, bool (n,).

    The others are lengths [m] (prismatic joints); ``--deg`` converts only the angles.
    """
    model = arm.model
    cols = [
        not _linear(model.joints[j])
        for j in range(1, model.njoints)
        for _ in range(model.joints[j].nv)
    ]
    return np.array(cols, dtype=bool)


# Eqn. (U1)
def degrees_to_radians(arm, values) -> np.ndarray:
    """``values`` (n,) or (n, k) per joint with the angular joints' rows converted from degrees (U1).

    ``q_j = π/180 · q_j,deg`` for revolute and continuous joints; rows of
    prismatic joints [m] are returned unchanged.

    Example:
        >>> from fault_tolerance import load_arm
        >>> degrees_to_radians(load_arm("planar_3r"), [0.0, 90.0, 45.0]).round(4).tolist()
        [0.0, 1.5708, 0.7854]
    """
    v = np.array(values, dtype=float)
    ang = angular_columns(arm)
    if v.shape[:1] != ang.shape:
        raise InvalidInput(
            f"{v.shape[0] if v.ndim else 1} values for {arm.n} joints {arm.joint_names}; give "
            "one per joint"
        )
    v[ang] = np.deg2rad(v[ang])
    return v


def _limited(bound: np.ndarray) -> np.ndarray:
    return np.abs(bound) < NO_LIMIT


def _looks_like_degrees(arm, q, refused: list[int]) -> bool:
    """True when the refused joints of ``q`` read as degrees: degree-sized and inside once converted.

    Degree-sized: an angular joint beyond a turn (:data:`TURN_LIMIT`), or every refused angular
    joint beyond π with the whole start inside the limits once its angles are read as degrees. A
    radian start a little past a limit (|q| ≤ π) gets no hint.
    """
    ang = angular_columns(arm)
    angles = [i for i in refused if ang[i]]
    if not angles:
        return False
    if any(abs(q[i]) > TURN_LIMIT for i in angles):
        return True
    if not all(abs(q[i]) > np.pi for i in angles):
        return False
    converted = wrap_into_limits(arm, degrees_to_radians(arm, q))
    return not bool(outside_limits(arm, converted).any())


def _describe(arm, q, i: int) -> str:
    """``joint2 = 90 rad (limits [-3.142, 3.142] rad)``; ``(no limits)`` where it has none."""
    unit = "rad" if angular_columns(arm)[i] else "m"
    lo, hi = arm.lower[i], arm.upper[i]
    lim = f"[{lo:.4g}, {hi:.4g}] {unit}" if _limited(lo) and _limited(hi) else "none"
    return f"{arm.joint_names[i]} = {q[i]:.6g} {unit} (limits {lim})"


# Eqn. (U2)
def start_problems(arm, q0, limits: bool = True) -> tuple[list[int], list[int]]:
    """Joints of a start ``q0`` that are refused: ``(beyond_a_turn, outside_limits)``.

    * beyond a turn: an angular joint with ``|q| > TURN_LIMIT`` that its limits (if any) do not
      allow — always refused, limits on or off;
    * outside limits: any joint outside its position limits (full-turn joints wrapped first,
      :func:`wrap_into_limits`) — refused only with ``limits`` on.
    """
    q = arm.check_q(q0, "q0")
    ang = angular_columns(arm)
    outside = outside_limits(arm, wrap_into_limits(arm, q))
    allowed = ~outside_limits(arm, q) & _limited(arm.lower) & _limited(arm.upper)
    turn = [i for i in range(arm.n) if ang[i] and abs(q[i]) > TURN_LIMIT and not allowed[i]]
    out = [i for i in np.flatnonzero(outside) if i not in turn] if limits else []
    return turn, [int(i) for i in out]


def check_start(arm, q0, limits: bool = True) -> np.ndarray:
    """``q0`` checked as a start: right size, finite, in radians, inside the limits (if on).

    Refused (:class:`InvalidInput`, naming each joint, its value and its limits): an angle beyond
    a turn outside its limits (with limits on or off), and with ``limits`` on any joint outside
    its position limits. When the refused values look like degrees (beyond a turn, or beyond π with the start
    inside the limits once converted from degrees) the message says so (:data:`DEGREES_HINT`).
    """
    q = arm.check_q(q0, "q0")
    turn, out = start_problems(arm, q, limits)
    if not turn and not out:
        return q
    hint = _looks_like_degrees(arm, q, turn + out)
    parts = []
    if turn:
        parts.append(
            f"q0 is beyond a turn (|q| > 2π·1.01 = {TURN_LIMIT:.4g} rad) at "
            + ", ".join(_describe(arm, q, i) for i in turn)
        )
    if out:
        parts.append(
            "q0 is outside the joint limits at " + ", ".join(_describe(arm, q, i) for i in out)
        )
    advice = "start inside them, or run without limits (limits=False, --no-limits)"
    if not out:
        advice = "angles are in radians"
    raise InvalidInput("; ".join(parts) + (f"; {DEGREES_HINT}" if hint else "") + f"; {advice}")


def check_found_start(arm, q0, where: str) -> None:
    """A start the tool found (the minimum-RCN posture at ``where``) checked inside the limits.

    Full-turn joints are wrapped into their limits first (:func:`wrap_into_limits`). Refused
    (:class:`InvalidInput`) naming each joint outside, its value and its limits; no degrees hint
    (the user did not give these values).
    """
    q = wrap_into_limits(arm, arm.check_q(q0, "q0"))
    out = np.flatnonzero(outside_limits(arm, q))
    if out.size:
        raise InvalidInput(
            f"the start found for {where} lies outside the joint limits: "
            + ", ".join(_describe(arm, q, int(i)) for i in out)
            + f"; move {where} inward, or run without limits (--no-limits)"
        )
