"""Checks that say when a run went wrong: one small function per problem, one warning each.

A run can finish and still be bad: rates far over the joints' velocity limits, reduced condition
numbers far beyond the paper's threshold, samples where J or a reduced robot was near-singular (the
rates were damped there), a tool that drifted off its path, a lock after which the reduced robot
could not follow the path. Each check below looks at one of these in a saved
:class:`~fault_tolerance.simulation.run.Run` and returns a :class:`RunWarning` (or ``None``);
:func:`check_run` runs them all. ``simulate``, ``lock`` and ``reproduce`` print one line per
warning and record them in ``summary.json`` under ``"warnings"``.

Tolerances (documented here and in the README):

* :data:`TRACKING_TOLERANCE` — largest task error ``‖x − x_des‖`` accepted while no joint is
  locked (1 mm).
* :data:`LOST_PATH_TOLERANCE` — how much the task error may grow after a lock above its largest
  value before the lock (1 cm): beyond it the lock "loses the path".

A lock run models the joint servos (a first-order lag on the commanded rates), and on a fast path
the lag alone puts the tool millimetres behind it. That part is the servo model's, not the
algorithm's. Given the lag-free reference (the same run, lock included, with perfect rate
tracking) :func:`tracking_error` and :func:`lock_loses_path` judge the reference's error, the
algorithm's and the reduced robot's, and :func:`servo_lag` says how much the lag adds before and
after the lock (a note, not a warning; after the lock it is the paper's path error, Sec. V),
docs/MATH.md (E1), (E2).

Example:
    >>> from fault_tolerance.simulation.diagnostics import check_run
    >>> [w.message for w in check_run(run)]  # doctest: +SKIP
    ['312 of 1001 samples over the velocity limit (worst: joint2, 7.2 rad/s = 2.4 x its 3 rad/s at t = 0.31 s)']
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.simulation.run import (
    FLAG_LOCKED,
    FLAG_NEAR_INTOLERABLE,
    FLAG_NEAR_SINGULAR,
    FLAG_OVER_SPEED,
    FLAG_TASK_SCALED,
    Run,
)

#: Largest task error [m] accepted while no joint is locked.
TRACKING_TOLERANCE = 1e-3
#: Growth of the task error [m] after a lock (over its peak before) above which the lock loses the path.
LOST_PATH_TOLERANCE = 1e-2
#: Relative slack on the velocity limits (a rate within it counts as at the limit, not over).
SPEED_SLACK = 1e-6


@dataclass(frozen=True)
class RunWarning:
    """One problem found in a run: a short kind (``over_speed``, ...) and a one-line message."""

    kind: str
    message: str

    def as_dict(self) -> dict:
        """``{"kind": ..., "message": ...}`` for summary.json."""
        return asdict(self)


def _names(run: Run) -> list[str]:
    return run.meta.get("joint_names") or [f"joint {j + 1}" for j in range(run.q.shape[1])]


def _span(run: Run, mask: np.ndarray) -> str:
    k = np.flatnonzero(mask)
    a, b = float(run.t[k[0]]), float(run.t[k[-1]])
    return f"at t = {a:.3g} s" if len(k) == 1 else f"between t = {a:.3g} and {b:.3g} s"


def over_speed(run: Run, velocity_limit: np.ndarray | None = None) -> RunWarning | None:
    """Samples whose commanded or actual joint rates exceed the velocity limits.

    With ``velocity_limit`` (the arm's, [rad/s]) the rates are compared here and the worst one is
    named; without, the run's ``FLAG_OVER_SPEED`` bits (set by ``simulate``) are counted.
    """
    rates = run.qd if run.qd_cmd is None else np.maximum(np.abs(run.qd), np.abs(run.qd_cmd))
    rates = np.abs(rates)
    if velocity_limit is None:
        over = (run.flags & FLAG_OVER_SPEED) != 0
        if not over.any():
            return None
        return RunWarning(
            "over_speed",
            f"{int(over.sum())} of {len(run.t)} samples over the velocity limit "
            f"({_span(run, over)}; largest rate {rates.max():.3g} rad/s)",
        )
    v = np.asarray(velocity_limit, dtype=float)
    v = np.where(np.isfinite(v) & (v > 0), v, np.inf)
    ratio = rates / v
    over = np.any(ratio > 1 + SPEED_SLACK, axis=1)
    if not over.any():
        return None
    k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return RunWarning(
        "over_speed",
        f"{int(over.sum())} of {len(run.t)} samples over the velocity limit (worst: "
        f"{_names(run)[j]}, {rates[k, j]:.3g} rad/s = {ratio[k, j]:.3g} x its {v[j]:.3g} rad/s "
        f"at t = {run.t[k]:.3g} s)",
    )


def rcn_beyond(run: Run, threshold: float = RCN_THRESHOLD) -> RunWarning | None:
    """Samples whose largest reduced condition number ``k_S`` (eq. 15) exceeds ``threshold``."""
    if run.rcn.size == 0:
        return None
    worst = run.rcn.max(axis=1)
    over = worst > threshold
    if not over.any():
        return None
    k = int(np.argmax(worst))
    sets = run.meta.get("lockable") or []
    s = int(np.argmax(run.rcn[k]))
    which = "+".join(sets[s]) if s < len(sets) else f"scenario {s + 1}"
    return RunWarning(
        "rcn",
        f"{int(over.sum())} of {len(run.t)} samples with a reduced condition number beyond the "
        f"paper's threshold {threshold:g} (largest k = {worst[k]:.3g} with {which} locked, "
        f"K = {run.K[k]:.3g}, at t = {run.t[k]:.3g} s)",
    )


def near_singular(run: Run) -> RunWarning | None:
    """Samples where J (after a lock: the remaining columns) was near-singular; rates damped."""
    mask = (run.flags & FLAG_NEAR_SINGULAR) != 0
    if not mask.any():
        return None
    return RunWarning(
        "near_singular",
        f"{int(mask.sum())} near-singular samples ({_span(run, mask)}; smallest singular value "
        f"of J {run.sigma_min.min():.3g}): the rates were damped there",
    )


def near_intolerable(run: Run) -> RunWarning | None:
    """Samples where a scenario's pivot N[S, S] was near zero: its lock would nearly lose the task."""
    mask = (run.flags & FLAG_NEAR_INTOLERABLE) != 0
    if not mask.any():
        return None
    return RunWarning(
        "near_intolerable",
        f"{int(mask.sum())} near-intolerable samples ({_span(run, mask)}): locking a lockable "
        "joint there would nearly lose the task; the pivots were damped",
    )


#: Largest joint rate [rad/s] that counts as "no motion" and smallest task rate that counts as motion.
ZERO_RATE = 1e-12


def zero_rates(run: Run) -> np.ndarray:
    """Samples whose commanded rates are all zero while the task moves (``ẋ_des ≠ 0``), shape (K,)."""
    qd = run.qd if run.qd_cmd is None else run.qd_cmd
    if len(run.t) < 2:
        return np.zeros(len(run.t), dtype=bool)
    xd = np.gradient(run.x_des, run.t, axis=0)  # the path's rate, from its samples
    moving = np.linalg.norm(xd, axis=1) > ZERO_RATE
    return moving & (np.max(np.abs(qd), axis=1) <= ZERO_RATE)


def task_scaled(run: Run) -> RunWarning | None:
    """Samples where the bounded rates kept only part of the task (s < 1, (L3)) or none of it.

    Counted are the samples flagged ``FLAG_TASK_SCALED`` (the joint limits made the resolver
    scale the task velocity) and those whose commanded rates are zero although the path moves
    (:func:`zero_rates`): the tool then falls behind its path by design, not by error.
    """
    scaled = (run.flags & FLAG_TASK_SCALED) != 0
    still = zero_rates(run)
    bad = scaled | still
    if not bad.any():
        return None
    parts = [f"{int(scaled.sum())} with the task scaled (s < 1)"] if scaled.any() else []
    if still.any():
        parts.append(f"{int(still.sum())} with zero rates while the path moves")
    return RunWarning(
        "task_scaled",
        f"{int(bad.sum())} of {len(run.t)} samples where the joint rates keep only part of the "
        f"task velocity ({'; '.join(parts)}; {_span(run, bad)}): the tool falls behind its path "
        "there",
    )


def _locked(run: Run) -> np.ndarray:
    lock = run.meta.get("lock")
    if lock:
        return run.t >= lock["time"] - 1e-12
    return (run.flags & FLAG_LOCKED) != 0


def _checked_reference(run: Run, lag_free: Run) -> Run:
    """``lag_free`` once it has the run's samples and lock (else a ``ValueError`` saying so)."""
    if lag_free.t.shape != run.t.shape or not np.allclose(lag_free.t, run.t, atol=1e-9):
        raise ValueError(
            f"the lag-free run has {len(lag_free.t)} samples to {lag_free.t[-1]:.3g} s; it must "
            f"have the run's {len(run.t)} samples to {run.t[-1]:.3g} s"
        )
    mine, theirs = (
        {k: v for k, v in (r.meta.get("lock") or {}).items() if k in ("joint", "time")}
        for r in (run, lag_free)
    )
    if mine != theirs:
        raise ValueError(f"the lag-free run locks {theirs or 'nothing'}; it must lock as the run "
                         f"does, {mine or 'nothing'}")  # fmt: skip
    return lag_free


def tracking_error(
    run: Run, tolerance: float = TRACKING_TOLERANCE, lag_free: Run | None = None
) -> RunWarning | None:
    """The algorithm's task error while no joint is locked exceeds ``tolerance`` [m].

    Without ``lag_free`` that is the run's own error. With it (the same run with perfect rate
    tracking, same samples and lock) it is the lag-free run's, (E2); the servo's lag is left to
    :func:`servo_lag`.
    """
    free = ~_locked(run)
    if not free.any():
        return None
    source = run if lag_free is None else _checked_reference(run, lag_free)
    err = np.where(free, source.error, 0.0)
    k = int(np.argmax(err))
    if err[k] <= tolerance:
        return None
    whose = "" if lag_free is None else " with perfect rate tracking (the algorithm's)"
    return RunWarning(
        "tracking",
        f"tracking error{whose} {1e3 * err[k]:.3g} mm at t = {run.t[k]:.3g} s is above the "
        f"tolerance {1e3 * tolerance:g} mm",
    )


# Eqn. (E1): the servo's lag, e_lag(t) = e(t) − e_ref(t) (the same run, perfect rate tracking).
def lag_excess(run: Run, lag_free: Run) -> np.ndarray:
    """The run's task error over the lag-free run's [m], per sample, shape (K,)."""
    return run.error - _checked_reference(run, lag_free).error


def servo_lag(run: Run, lag_free: Run, tolerance: float = TRACKING_TOLERANCE) -> str | None:
    """A note on the error the servo's lag adds (E1), before and after the lock, or ``None``.

    Given when the run's error exceeds ``tolerance`` [m] somewhere: how much of it the lag-free
    run has (the algorithm's and, after the lock, the reduced robot's) and how much the lag adds
    (the servo model's).
    """
    if run.error.max() <= tolerance:
        return None
    excess = lag_excess(run, lag_free)
    locked = _locked(run)
    parts = []
    for label, mask in (("before the lock", ~locked), ("after it", locked)):
        if mask.any():
            parts.append(
                f"{1e3 * run.error[mask].max():.3g} mm {label} "
                f"({1e3 * lag_free.error[mask].max():.3g} mm with perfect rate tracking; the lag "
                f"adds up to {1e3 * excess[mask].max():.3g} mm)"
            )
    return f"servo lag: task error with the servo model {', '.join(parts)}"


# Eqn. (E2): the verdicts read e_ref, the same run with perfect rate tracking.
def lock_loses_path(
    run: Run, tolerance: float = LOST_PATH_TOLERANCE, lag_free: Run | None = None
) -> RunWarning | None:
    """After the lock the task error grows more than ``tolerance`` [m] above its level before.

    The error the run already had before the lock (e.g. the servos' lag, reported by
    :func:`tracking_error`) is not counted against the lock. With ``lag_free`` (the same run with
    perfect rate tracking) the error judged is the lag-free run's (E2): whether the reduced robot
    follows the path, not how far the lagging servos fall behind at the jump.
    """
    lock = run.meta.get("lock")
    after = _locked(run)
    if not lock or not after.any():
        return None
    error = run.error if lag_free is None else _checked_reference(run, lag_free).error
    before = float(error[~after].max()) if (~after).any() else 0.0
    err = np.where(after, error, 0.0)
    k = int(np.argmax(err))
    if err[k] - before <= tolerance:
        return None
    whose = "" if lag_free is None else " with perfect rate tracking"
    return RunWarning(
        "lost_path",
        f"the lock of {lock['joint']} at t = {lock['time']:.3g} s loses the path: error{whose} "
        f"{1e3 * err[k]:.3g} mm at t = {run.t[k]:.3g} s, {1e3 * before:.3g} mm before the lock "
        f"(tolerance {1e3 * tolerance:g} mm more; {1e3 * error[-1]:.3g} mm at the end)",
    )


def check_run(run: Run, arm=None, *, lag_free: Run | None = None) -> list[RunWarning]:
    """Every check on ``run``; ``arm`` (optional) gives the velocity limits for the rate check.

    ``lag_free`` (optional, same samples and lock): the run with perfect rate tracking; with it
    the tracking and lost-path checks leave the servo's lag out (:func:`tracking_error`,
    :func:`lock_loses_path`, (E2)).
    """
    vmax = None if arm is None else arm.velocity_limit
    found = [
        over_speed(run, vmax),
        rcn_beyond(run),
        near_singular(run),
        near_intolerable(run),
        task_scaled(run),
        tracking_error(run, lag_free=lag_free),
        lock_loses_path(run, lag_free=lag_free),
    ]
    return [w for w in found if w is not None]


def warning_lines(label: str, warnings: list[RunWarning]) -> list[str]:
    """One printable line per warning: ``warning: LABEL: MESSAGE``."""
    return [f"warning: {label}: {w.message}" for w in warnings]
