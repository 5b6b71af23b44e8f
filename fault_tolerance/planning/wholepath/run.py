"""``simulate(arm, path, "global", ...)``: plan the whole path, then run the plan like any other.

The plan (:func:`~.plan.plan_path`) gives reference configurations; the run tracks them in the null
space (MATH.md (W3)) inside :func:`~fault_tolerance.simulation.simulate.simulate`'s own loop, so the run's
λ(t), K(t), tracking error, flags, lock events and servo model are computed exactly as for LNVA,
JVJA and MDA. Without a lock the run is then compared with simulate's own LNVA and JVJA runs from
the same start and the best one (within the limits first, then the objective) is returned under the
name ``global``: from the same start its objective is never above theirs.

This module sits below :mod:`~fault_tolerance.simulation.simulate`: simulate hands its own loop in
(``loop``), so nothing here imports simulation and the run does not come back through it.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.planning.wholepath.plan import plan_path
from fault_tolerance.simulation.setup import GLOBAL
from fault_tolerance.simulation.simulate import PATH_PLANNER_STYLES, PATH_PLANNERS

#: Options of the planner that ``simulate(..., plan_options={...})`` passes on.
PLAN_OPTIONS = ("objective", "method", "limits", "rcn_max", "iterations", "dp_step", "dp_stage")


def check_plan_options(plan_options) -> dict:
    """``plan_options`` as a dict of known planner options, or :class:`InvalidInput`."""
    opts = dict(plan_options or {})
    unknown = sorted(set(opts) - set(PLAN_OPTIONS))
    if unknown:
        raise InvalidInput(
            f"plan option(s) {unknown} are not known; allowed are {list(PLAN_OPTIONS)}"
        )
    return opts


def _objective(run, objective: str) -> float:
    return float(np.mean(run.jvj) if objective == "mean" else np.max(run.jvj))


def _over_limits(arm, run, limits: bool) -> bool:
    """True when the run leaves the position limits or exceeds a velocity limit."""
    if not limits:
        return False
    from fault_tolerance.model.joint_limits import outside_limits, velocity_limits

    fast = np.any(np.abs(run.qd) > velocity_limits(arm) * (1 + 1e-9))
    return bool(fast or np.any(outside_limits(arm, run.q)))


def _shows(progress) -> bool:
    """Whether the caller's progress object is a visible bar (then the plan shows one too)."""
    if progress is None or getattr(progress, "disable", False):
        return False
    return getattr(progress, "bar", True) is not None


def simulate_global(arm, path, *, q0, plan_options, progress, loop, **sim):
    """The global run (see the module doc): plan, run the plan, keep the best of it, LNVA, JVJA.

    ``loop`` is simulate's loop (``simulation._simulate``: ``loop(arm, path, algorithm, q0=...,
    progress=..., reference=..., **sim)``); LNVA and JVJA run through it exactly as ``simulate``
    runs them (``engine="auto"``).
    """
    opts = check_plan_options(plan_options)
    if sim.get("response", "least_norm") != "least_norm":
        raise InvalidInput(
            "the global plan minimises the jump under the least-norm response (2); "
            "use response='least_norm'"
        )
    plan = plan_path(
        arm,
        path,
        q0=q0,
        lockable=sim.get("lockable"),
        weights=sim.get("weights"),
        dt=sim.get("dt", 1e-3),
        duration=sim.get("duration"),
        feedback_gain=sim.get("feedback_gain", 0.0),
        progress=_shows(progress),
        **opts,
    )
    limits = opts.get("limits", True)
    if plan.warm_start_used:  # the local run is the plan: run it as itself
        run = loop(arm, path, plan.warm_start_used, q0=plan.q0, progress=progress, **sim)
    else:
        run = loop(arm, path, "global", q0=plan.q0, progress=progress, reference=plan.q_ref, **sim)
    choice = "plan"
    if sim.get("lock_joint") is None:  # the guarantee, on simulate's own numbers
        runs = {"plan": run}
        for alg in ("lnva", "jvja"):
            runs[alg] = loop(arm, path, alg, q0=plan.q0, **sim)
        choice = min(
            runs,
            key=lambda a: (_over_limits(arm, runs[a], limits), _objective(runs[a], plan.objective)),
        )
        run = runs[choice]
    run.meta["algorithm"] = "global"
    run.meta["global"] = plan.summary() | {"run": choice}
    return run


PATH_PLANNERS[GLOBAL] = simulate_global
PATH_PLANNER_STYLES[GLOBAL] = ("#9467bd", "global (whole-path plan)")
