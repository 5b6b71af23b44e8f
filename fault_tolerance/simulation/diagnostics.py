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
* :data:`~fault_tolerance.planning.posture.RCN_THRESHOLD` — the largest reduced condition number ``k_S``
  accepted along a run (the planning loop's threshold, Sec. III.D step iii).
* the velocity limits of the URDF (``<limit velocity=...>``), with :data:`SPEED_SLACK` relative
  slack for rounding.

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


def tracking_error(run: Run, tolerance: float = TRACKING_TOLERANCE) -> RunWarning | None:
    """The task error while no joint is locked exceeds ``tolerance`` [m]."""
    free = ~_locked(run)
    if not free.any():
        return None
    err = np.where(free, run.error, 0.0)
    k = int(np.argmax(err))
    if err[k] <= tolerance:
        return None
    return RunWarning(
        "tracking",
        f"tracking error {1e3 * err[k]:.3g} mm at t = {run.t[k]:.3g} s is above the "
        f"tolerance {1e3 * tolerance:g} mm",
    )


def lock_loses_path(run: Run, tolerance: float = LOST_PATH_TOLERANCE) -> RunWarning | None:
    """After the lock the task error grows more than ``tolerance`` [m] above its level before.

    The error the run already had before the lock (e.g. the servos' lag, reported by
    :func:`tracking_error`) is not counted against the lock.
    """
    lock = run.meta.get("lock")
    after = _locked(run)
    if not lock or not after.any():
        return None
    before = float(run.error[~after].max()) if (~after).any() else 0.0
    err = np.where(after, run.error, 0.0)
    k = int(np.argmax(err))
    if err[k] - before <= tolerance:
        return None
    return RunWarning(
        "lost_path",
        f"the lock of {lock['joint']} at t = {lock['time']:.3g} s loses the path: error "
        f"{1e3 * err[k]:.3g} mm at t = {run.t[k]:.3g} s, {1e3 * before:.3g} mm before the lock "
        f"(tolerance {1e3 * tolerance:g} mm more; {1e3 * run.error[-1]:.3g} mm at the end)",
    )


def check_run(run: Run, arm=None) -> list[RunWarning]:
    """Every check on ``run``; ``arm`` (optional) gives the velocity limits for the rate check."""
    vmax = None if arm is None else arm.velocity_limit
    found = [
        over_speed(run, vmax),
        rcn_beyond(run),
        near_singular(run),
        near_intolerable(run),
        task_scaled(run),
        tracking_error(run),
        lock_loses_path(run),
    ]
    return [w for w in found if w is not None]


def warning_lines(label: str, warnings: list[RunWarning]) -> list[str]:
    """One printable line per warning: ``warning: LABEL: MESSAGE``."""
    return [f"warning: {label}: {w.message}" for w in warnings]
