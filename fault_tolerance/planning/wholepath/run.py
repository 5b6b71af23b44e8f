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
    if sim.get("lock_joint") is not None:  # no comparison: the planner's own scores, said so
        run.meta["algorithm"] = "global"
        run.meta["global"] = plan.summary() | {
            "run": "plan",
            "scores_from": "the planner's model of the run without a lock",
        }
        return run
    runs = {"plan": run}  # the guarantee, on simulate's own numbers
    for alg in ("lnva", "jvja"):
        runs[alg] = loop(arm, path, alg, q0=plan.q0, **sim)
    choice = min(
        runs,
        key=lambda a: (_over_limits(arm, runs[a], limits), _objective(runs[a], plan.objective)),
    )
    run = runs[choice]
    run.meta["algorithm"] = "global"
    run.meta["global"] = _run_summary(plan, runs, choice)
    return run


def _run_summary(plan, runs: dict, choice: str) -> dict:
    """The plan's metadata with the scores of the runs themselves (what summary.json reports).

    ``scores``: the objective of the plan's run, of LNVA's and JVJA's runs from the same start and
    of the run reported (``final``), [(rad/s)²]; the planner's own estimates stay under
    ``planned_scores`` / ``planned_improvement``. ``improvement`` is over the warm start's run,
    ``improvement_over_best_local`` over the better of LNVA and JVJA; ``note`` says when the plan
    is not a plan of its own (a local run is reported, or the plan is that run).
    """
    scores = {a: _objective(r, plan.objective) for a, r in runs.items()}
    scores["final"] = scores[choice]
    local = min(("lnva", "jvja"), key=lambda a: scores[a])
    gain = max(0.0, (scores[local] - scores["final"]) / max(abs(scores[local]), 1e-300))
    warm = scores.get(plan.warm_start, scores[local])
    over_warm = max(0.0, (warm - scores["final"]) / max(abs(warm), 1e-300))
    out = plan.summary()
    out["planned_scores"] = out.pop("scores")
    out["planned_improvement"] = out.pop("improvement")
    out |= {"scores": scores, "improvement": over_warm, "improvement_over_best_local": gain,
            "best_local": local, "run": choice}  # fmt: skip
    what = f"the {plan.objective} of λ"
    if choice != "plan":
        out["note"] = (
            f"no plan beat the {choice} run from the same start on {what} "
            f"({scores['final']:.4g} (rad/s)²); global reports that run"
        )
    elif plan.warm_start_used:
        out["note"] = (
            f"the optimiser found nothing below the {plan.warm_start_used} run on {what} from "
            f"this start ({scores['final']:.4g} (rad/s)²): the plan is that run"
        )
    elif gain <= 0.0:
        out["note"] = f"the plan ties the {local} run on {what} ({scores['final']:.4g} (rad/s)²)"
    return out


PATH_PLANNERS[GLOBAL] = simulate_global
PATH_PLANNER_STYLES[GLOBAL] = ("#ff7f0e", "global (whole-path plan)")
