"""The whole-path planner: warm starts, DP (r = 1), SCP, and the best feasible plan (MATH.md (W)).

:func:`plan_path` returns a :class:`Plan`: the reference configurations ``q_ref`` the arm follows
in the null space (``q̇_k = J⁺ẋ_cmd + N (q_ref[k+1] − q_k)/dt``), the start, which method produced
it and by how much it beats its warm start. LNVA's and JVJA's own trajectories are candidates,
so the plan's objective is never above theirs (from the same start).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.planning.wholepath.dp import _correct, dp_plan
from fault_tolerance.planning.wholepath.problem import (
    OBJECTIVES,
    Trajectory,
    build_problem,
    rollout,
)
from fault_tolerance.planning.wholepath.scp import _better, scp

#: Planner methods: ``auto`` (DP then SCP for r = 1, SCP otherwise), ``dp`` (r = 1), ``scp``.
METHODS = ("auto", "dp", "scp")


@dataclass
class Plan:
    """A whole-path plan and how it was found.

    Attributes:
        q_ref: Reference configurations at t_k, shape (T+1, n) (the planned trajectory).
        q0: The start, shape (n,) (``q0`` itself when it was given).
        qd: Planned rates, shape (T+1, n).
        lam: Planned square-sum jump λ(t_k), shape (T+1,).
        method: What produced the plan: ``"dp+scp"``, ``"dp"``, ``"scp"`` or ``"warm start (jvja)"``
            / ``"warm start (lnva)"`` when nothing beat the local runs.
        objective: ``"mean"`` or ``"max"`` of λ.
        scores: Objective of every candidate (``lnva``, ``jvja``, ``dp``, ``dp+scp``, ``scp``).
        warm_start: The local run the optimiser started from (``lnva`` or ``jvja``).
        improvement: Relative improvement of the plan over that warm start (≥ 0).
        info: Iterations, grid sizes, seconds.
    """

    q_ref: np.ndarray
    q0: np.ndarray
    qd: np.ndarray
    lam: np.ndarray
    method: str
    objective: str
    scores: dict
    warm_start: str
    improvement: float
    fixed_start: bool
    info: dict = field(default_factory=dict)

    @property
    def warm_start_used(self) -> str | None:
        """``"lnva"`` or ``"jvja"`` when that local run itself is the plan, else None."""
        if self.method.startswith("warm start ("):
            return self.method[len("warm start (") : -1]
        return None

    def summary(self) -> dict:
        """JSON-able description (saved in a run's meta)."""
        return {
            "method": self.method,
            "objective": self.objective,
            "warm_start": self.warm_start,
            "improvement": self.improvement,
            "fixed_start": self.fixed_start,
            "scores": self.scores,
            **self.info,
        }


def plan_path(
    arm: Arm,
    path,
    *,
    q0: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    lockable=None,
    weights=None,
    dt: float = 1e-3,
    duration: float | None = None,
    feedback_gain: float = 0.0,
    limits: bool = True,
    rcn_max: float | None = None,
    objective: str = "mean",
    method: str = "auto",
    iterations: int = 80,
    dp_step: float = 0.01,
    dp_stage: float = 0.05,
    progress=None,
) -> Plan:
    """Plan the whole path for the smallest mean (or maximum) jump λ(t).

    Args:
        arm: The arm.
        path: The task path (as for :func:`~fault_tolerance.simulation.simulate.simulate`).
        q0: Fixed start (kept exactly). Without it the start is free on the self-motion of
            ``x0`` (default: the path's start), searched from the minimum-RCN posture.
        x0: Task point of a free start (only without ``q0``).
        lockable: Joints that may lock (failure scenarios), as for the other planners.
        weights: Scenario weights, as for the other planners.
        dt: Time step [s], as for ``simulate`` (the same discretisation).
        duration: Length [s] (default: the path's), as for ``simulate``.
        feedback_gain: Task feedback ``K_p`` [1/s], as for ``simulate``.
        limits: Enforce the URDF joint position and velocity limits.
        rcn_max: Optional bound on every reduced condition number ``k_S`` (Sec. III.D).
        objective: ``"mean"`` or ``"max"`` of λ over the path.
        method: ``"auto"``, ``"dp"`` (r = 1 only) or ``"scp"``.
        iterations: Most SCP iterations.
        dp_step: DP grid: arclength spacing [rad].
        dp_stage: DP grid: stage interval [s].
        progress: ``True`` for a tqdm bar, or a tqdm-like object with ``update``.

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> from fault_tolerance.paper.reproduce import CASES
        >>> case = CASES["fig7"]; arm = ft.load_arm(case.robot)
        >>> q0 = np.array([0.2574, 1.2106, -0.9513, 1.9333])
        >>> plan = plan_path(arm, case.path(0.2), q0=q0, lockable=list(case.lockable))
        >>> plan.scores["final"] <= min(plan.scores["lnva"], plan.scores["jvja"])
        True
    """
    _check_options(arm, method, objective, iterations)
    prob = build_problem(
        arm,
        path,
        dt=dt,
        steps=_steps(path, duration, dt),
        lockable=lockable,
        weights=weights,
        feedback_gain=feedback_gain,
        limits=limits,
        rcn_max=rcn_max,
        objective=objective,
    )
    fixed = q0 is not None
    start = arm.check_q(q0) if q0 is not None else _free_start(arm, path, x0, prob)
    bar, own = _bar(progress, iterations + (2 if arm.redundancy == 1 and method != "scp" else 0))
    tic = time.perf_counter()
    try:
        return _plan(prob, start, fixed, method, iterations, dp_step, dp_stage, bar, tic)
    finally:
        if own:
            bar.close()


def _check_options(arm: Arm, method: str, objective: str, iterations) -> None:
    """Refuse an unknown method or objective, DP without r = 1, or a bad iteration count."""
    if method not in METHODS:
        raise InvalidInput(f"global planner method {method!r} is not one of {list(METHODS)}")
    if objective not in OBJECTIVES:
        raise InvalidInput(f"objective {objective!r} is not one of {list(OBJECTIVES)}")
    if method == "dp" and arm.redundancy != 1:
        raise InvalidInput(
            f"method 'dp' needs one degree of redundancy; {arm.name} has r = {arm.redundancy} "
            "for this task: use method 'scp' or 'auto'"
        )
    if not (isinstance(iterations, int) and iterations >= 0):
        raise InvalidInput(f"iterations must be an integer >= 0, got {iterations!r}")


def _steps(path, duration: float | None, dt: float) -> int:
    """Time steps of the plan (as ``simulate`` counts them), or :class:`InvalidInput`."""
    duration = path.duration if duration is None else float(duration)
    steps = int(round(duration / dt))
    if not (np.isfinite(dt) and dt > 0 and steps >= 1):
        raise InvalidInput(f"dt = {dt} and duration = {duration} give no time step")
    return steps


def _plan(prob, start, fixed, method, iterations, dp_step, dp_stage, bar, tic) -> Plan:
    cands: dict[str, Trajectory] = {
        "lnva": rollout(prob, start, "lnva"),
        "jvja": rollout(prob, start, "jvja"),
    }
    warm_name = "jvja" if _better(cands["jvja"], cands["lnva"], 1e-9) else "lnva"
    warm = cands[warm_name]
    info: dict = {}
    own_start = warm
    if warm.violation <= 1e-9 and warm.score <= 1e-24:  # λ ≡ 0 (eq. 8): nothing can beat it
        info["zero_jump"] = True
    elif prob.arm.redundancy == 1 and method in ("auto", "dp"):
        res = dp_plan(prob, warm.q, fixed_start=fixed, h=dp_step, stage_dt=dp_stage, progress=bar)
        if res is not None:
            q_start = start if fixed else res.q_ref[0]
            cands["dp"] = rollout(prob, q_start, "track", q_ref=res.q_ref)
            info.update(
                dp_value=res.value,
                dp_stages=res.stages,
                dp_nodes=res.nodes,
                dp_band=res.band,
                dp_step=res.h,
                dp_stage_dt=res.stage_dt,
            )
            if _better(cands["dp"], warm, 1e-9):
                own_start = cands["dp"]
        if method == "auto" and iterations:
            out = scp(prob, own_start, fixed_start=fixed, iterations=iterations, progress=bar)
            cands["dp+scp" if own_start is not warm else "scp"] = out.best
            info.update(scp_iterations=out.iterations, scp_accepted=out.accepted)
    else:
        out = scp(prob, warm, fixed_start=fixed, iterations=iterations, progress=bar)
        cands["scp"] = out.best
        info.update(scp_iterations=out.iterations, scp_accepted=out.accepted)
    best_name = min(cands, key=lambda k: (cands[k].violation > 1e-9, cands[k].score))
    best = cands[best_name]
    scores = {k: v.score for k, v in cands.items()}
    scores["final"] = best.score
    violations = {k: v.violation for k, v in cands.items()}
    info.update(seconds=time.perf_counter() - tic, violations=violations, steps=prob.T)
    ref = best_name if best_name not in ("lnva", "jvja") else f"warm start ({best_name})"
    improvement = max(0.0, (warm.score - best.score) / max(abs(warm.score), 1e-300))
    return Plan(
        q_ref=best.q,
        q0=best.q[0].copy(),
        qd=best.qd,
        lam=best.lam,
        method=ref,
        objective=prob.objective,
        scores=scores,
        warm_start=warm_name,
        improvement=improvement,
        fixed_start=fixed,
        info=info,
    )


def _free_start(arm: Arm, path, x0, prob) -> np.ndarray:
    """Start for a free-start plan: the minimum-RCN posture at ``x0`` (paper Sec. III.D, step i)."""
    from fault_tolerance.planning.posture import initial_posture

    start = np.asarray(path.x(0.0), dtype=float)
    x0 = start if x0 is None else np.asarray(x0, dtype=float)
    if x0.shape != start.shape or not np.allclose(x0, start, atol=1e-9):
        raise InvalidInput(
            f"x0 = {np.asarray(x0).tolist()} is not the path's start {start.tolist()}; a free start "
            "lies on the self-motion of the path's first point"
        )
    q = initial_posture(arm, x0, lockable=prob.sc).q
    return _correct(prob, q[None], np.array([0]), iters=4)[0]


def _bar(progress, total: int):
    """A tqdm bar for ``progress=True``; the object itself when it has ``update``; else None."""
    if progress is True:
        from tqdm.auto import tqdm

        return tqdm(total=total, desc="global plan", unit="step", leave=False), True
    if progress is None or progress is False:
        return None, False
    if not hasattr(progress, "update"):
        raise InvalidInput("progress must be True, False, None or an object with update()")
    return progress, False
