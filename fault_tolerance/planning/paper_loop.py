"""The planning loop of the paper's Sec. III.D, steps (ii)-(iii): run, check, try the next start.

:func:`plan` runs the path from the best start of :func:`~.posture.initial_posture` (step i),
compares the largest reduced condition number met with a threshold, and tries the next-best start
configurations (the other local minima of ``K``) until one holds. It sits above
:mod:`.simulation` (it runs it); :mod:`.posture` sits below, so nothing comes back.

Example:
    >>> import numpy as np, fault_tolerance as ft
    >>> from fault_tolerance.simulation.paths import CirclePath
    >>> arm = ft.load_arm("planar_3r")
    >>> path = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.02)
    >>> run, attempts = plan(arm, path, "jvja", limits=False)
    >>> attempts[-1].accepted
    True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fault_tolerance.model.arm import Arm
from fault_tolerance.planning.posture import Posture, initial_posture
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.simulation.simulate import simulate


@dataclass
class PlanAttempt:
    """One start configuration tried by :func:`plan`."""

    q0: np.ndarray
    K0: float
    rcn_max: float
    accepted: bool
    reason: str


def plan(
    arm: Arm,
    path,
    algorithm: str = "jvja",
    *,
    lockable=None,
    threshold: float = RCN_THRESHOLD,
    max_attempts: int = 5,
    posture: Posture | None = None,
    **sim_options,
):
    """Steps (i)-(iii) of Sec. III.D: best start, run, accept if ``max k_S <= threshold``.

    Returns ``(run, attempts)``: the accepted run (or, if none holds, the one with the smallest
    largest RCN) and the list of :class:`PlanAttempt` saying which start was chosen and why.
    """
    posture = posture or initial_posture(arm, path.x0, lockable)
    tried: list[tuple[PlanAttempt, object]] = []
    for K0, q0 in posture.candidates[:max_attempts]:
        run = simulate(arm, path, algorithm, q0=q0, lockable=lockable, **sim_options)
        worst = float(np.max(run.rcn))
        ok = worst <= threshold
        reason = (
            f"largest RCN {worst:.3g} <= threshold {threshold:g}"
            if ok
            else f"largest RCN {worst:.3g} > threshold {threshold:g}; trying the next start"
        )
        tried.append((PlanAttempt(q0, K0, worst, ok, reason), run))
        if ok:
            break
    if not any(a.accepted for a, _ in tried):
        best = min(range(len(tried)), key=lambda i: tried[i][0].rcn_max)
        tried[best][0].reason += "; no start met the threshold, keeping the one with the smallest"
        return tried[best][1], [a for a, _ in tried]
    return tried[-1][1], [a for a, _ in tried]
