"""The tests a start must pass: limits, regularity, tolerable scenarios, a clean run.

Used by :func:`fault_tolerance.planning.default_start.default_start` (docs/MATH.md, "The default start").
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.model.arm import Arm
from fault_tolerance.model.task_errors import error_norms
from fault_tolerance.numerics.linalg import PIVOT_TOL, projection
from fault_tolerance.planning.posture import lockable_scenarios
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.resolution.scenarios import Scenarios

#: Distance a start keeps from every joint limit, as a fraction of the joint's range.
LIMIT_MARGIN = 0.05
#: Smallest singular value of J [task units per rad] a start must have.
SIGMA_REGULAR = 1e-2
#: Smallest pivot of N[S, S] a start must have for every lockable scenario (intolerable: < 1e-9).
PIVOT_MARGIN = 1e-3
#: Largest position error [m] (and orientation error [rad]) a checked run may reach.
ERROR_TOL = 1e-3
#: Random regular configurations at which a scenario must be intolerable to count as structural.
STRUCTURAL_SAMPLES = 50


def limit_box(arm: Arm) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits with infinite ones replaced by ±π (continuous joints are read as ±π)."""
    lo = np.where(np.isfinite(arm.lower), arm.lower, -np.pi)
    hi = np.where(np.isfinite(arm.upper), arm.upper, np.pi)
    return lo, hi


def mid_range(arm: Arm) -> np.ndarray:
    """The configuration halfway between every joint's limits (0 for continuous joints)."""
    lo, hi = limit_box(arm)
    return (lo + hi) / 2


def inside_limits(arm: Arm, q: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Which rows of ``q`` (shape (..., n)) keep ``margin`` × range from every joint limit."""
    lo, hi = limit_box(arm)
    pad = margin * (hi - lo)
    q = np.asarray(q, dtype=float)
    return np.all((q >= lo + pad - 1e-12) & (q <= hi - pad + 1e-12), axis=-1)


def start_problem(arm: Arm, q: np.ndarray, sc: Scenarios) -> str | None:
    """Why ``q`` is not a usable start (limits, singular J, intolerable scenario), or ``None``."""
    if not inside_limits(arm, q, LIMIT_MARGIN):
        return f"within {100 * LIMIT_MARGIN:g} % of a joint limit"
    proj = projection(arm.jacobian(q))
    if proj.sigma_min < SIGMA_REGULAR:
        return f"near-singular (σ_min(J) = {proj.sigma_min:.2g} < {SIGMA_REGULAR:g})"
    pivots = sc.pivots(proj.N)
    k = int(np.argmin(pivots))
    if pivots[k] < PIVOT_MARGIN:
        return (
            f"locking {', '.join(sc.name(sc.sets[k]))} nearly loses the task there "
            f"(pivot {pivots[k]:.2g} < {PIVOT_MARGIN:g})"
        )
    return None


def under_limits_at_start(arm: Arm, q: np.ndarray, task, sc: Scenarios, sim_options: dict):
    """Scenarios that cannot keep the task's first velocity inside the rate box at ``q`` (L1), (L4).

    ``None`` when joint limits are off (``sim_options["limits"] is False``) or there is no task:
    nothing to check. Otherwise the names (``"joint2"``, ``"joint1+joint2"``) of the scenarios
    whose reduced robot needs a task scaling ``s_S < 1`` at ``t = 0``, with the box the run uses
    (horizon ``max(horizon, dt)``) and the velocity it commands there (``ẋ_des(0)``, the start
    being on the path).
    """
    from fault_tolerance.model.joint_limits import RATE_HORIZON, arm_rate_box
    from fault_tolerance.resolution.bounded import SCALE_TOL
    from fault_tolerance.resolution.limits import tolerable_under_limits

    if task is None or not sim_options.get("limits", True):
        return None
    h = sim_options.get("horizon") or RATE_HORIZON
    box = arm_rate_box(arm, q, max(float(h), float(sim_options.get("dt", 0.0) or 0.0)))
    xd = np.asarray(task.xdot(0.0), dtype=float)
    scales = tolerable_under_limits(arm.jacobian(q), xd, sc, bounds=box)
    return tuple(
        "+".join(sc.name(S)) for S, s in zip(sc.sets, scales, strict=True) if s < 1.0 - SCALE_TOL
    )


def run_problem(arm: Arm, run) -> str | None:
    """Why a checked run disqualifies its start (limits, singular J, task error), or ``None``."""
    from fault_tolerance.simulation.run import FLAG_NEAR_SINGULAR

    out = ~inside_limits(arm, run.q)
    if out.any():
        k = int(np.argmax(out))
        return f"leaves the joint limits at t = {run.t[k]:.3f} s"
    if np.any(run.flags & FLAG_NEAR_SINGULAR):
        return "passes near a singularity of J"
    if run.error.max() > ERROR_TOL:
        return f"position error reaches {1e3 * run.error.max():.3g} mm"
    ori = run.orientation_error
    if ori is not None and ori.max() > ERROR_TOL:
        return f"orientation error reaches {ori.max():.3g} rad"
    return None


def run_caveat(run) -> str | None:
    """What makes a run that passed :func:`run_problem` less than ideal, or ``None``."""
    from fault_tolerance.simulation.run import FLAG_NEAR_INTOLERABLE

    near = int(np.count_nonzero(run.flags & FLAG_NEAR_INTOLERABLE))
    if near:
        return f"{near} samples where a lockable joint is nearly intolerable (pivots damped)"
    worst = float(np.max(run.rcn))
    if worst > RCN_THRESHOLD:
        return f"largest k_S {worst:.3g} > RCN threshold {RCN_THRESHOLD:g}"
    return None


def task_error_parts(task, x_des, x, *, arm: Arm | None = None, q=None):
    """Position error [m] and orientation error [rad] (``None`` without angular rows) per sample.

    With ``arm`` and ``q`` the angular part is the rotation that remains (``Arm.task_error``);
    otherwise the difference of the rotation-vector rows. See :mod:`.task_errors`.
    """
    x_des, x = np.atleast_2d(x_des), np.atleast_2d(x)
    if arm is not None and q is not None:
        err = np.array(
            [arm.task_error(xd, qk) for xd, qk in zip(x_des, np.atleast_2d(q), strict=True)]
        )
    else:
        err = x_des - x
    return error_norms(tuple(task), err)


def intolerable_everywhere(
    arm: Arm, lockable, samples: int = STRUCTURAL_SAMPLES, seed: int = 0
) -> list[tuple[str, ...]]:
    """Scenarios intolerable at every one of ``samples`` random regular configurations (seeded).

    A configuration is regular when ``σ_min(J) >= 1e-3``; intolerable means the smallest pivot of
    ``N[S, S]`` is below ``1e3 · PIVOT_TOL`` there. The spatial 4R's ``joint4`` is one.
    """
    sc = lockable_scenarios(arm, lockable)
    rng = np.random.default_rng(seed)
    always = set(range(sc.f))
    seen = 0
    for _ in range(20 * samples):
        proj = projection(arm.jacobian(arm.random_q(rng)))
        if proj.sigma_min < 1e-3:
            continue
        pivots = sc.pivots(proj.N)
        always &= {k for k in always if pivots[k] < 1e3 * PIVOT_TOL}
        seen += 1
        if seen == samples or not always:
            break
    return [tuple(sc.name(sc.sets[k])) for k in sorted(always)]
