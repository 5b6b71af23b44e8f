"""The paper's runs: each case with LNVA, JVJA and MDA, the Sec. V lock experiment, two checks.

The second stop of ``reproduce``: :func:`run_case` plans the start (Sec. III.D) and runs the three
algorithms on one :class:`~.paper_cases.Case`; :func:`run_experiment` runs the Power-Cube lock; the
``*_summary`` functions turn the runs into the entries of ``summary.json`` (DESIGN.md's contract)
and their diagnostics; :func:`eq8_check` and :func:`step_timing` are the checks of claims 5 and 9.
"""

from __future__ import annotations

import time

import numpy as np

from fault_tolerance.model.arm import Arm
from fault_tolerance.model.loading import load_arm
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.paper.cases import ALGORITHMS, CASES, EXPERIMENT, Case, LockExperiment
from fault_tolerance.planning.paper_loop import plan
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.resolution.resolvers import jump_reduction
from fault_tolerance.simulation.run import Run
from fault_tolerance.simulation.simulate import simulate


def run_case(
    case: Case, *, duration: float | None = None, progress=None, arm: Arm | None = None
) -> dict:
    """Sec. III.D planning, then one run per algorithm from the chosen start.

    Step (i) finds the minimum-RCN start; steps (ii)-(iii) run JVJA from it and accept it when the
    largest reduced condition number stays under :data:`~.posture.RCN_THRESHOLD`, else try the
    next local minimum. LNVA and MDA start from the same configuration. Returns ``{"arm",
    "posture", "runs", "path", "attempts", "q0"}``.
    """
    arm = arm or load_arm(case.robot)
    lockable = list(case.lockable)
    posture = initial_posture(arm, np.array(case.x0), lockable)
    path = case.path(duration)
    jvja_run, attempts = plan(
        arm, path, "jvja", lockable=lockable, posture=posture, progress=progress, limits=False
    )
    if len(attempts) > 1 and hasattr(progress, "grow"):
        progress.grow((len(attempts) - 1) * len(jvja_run.t))
    q0 = np.array(jvja_run.meta["q0"])
    runs = {
        alg: jvja_run
        if alg == "jvja"
        else simulate(arm, path, alg, q0=q0, lockable=lockable, progress=progress, limits=False)
        for alg in ALGORITHMS
    }
    return {
        "arm": arm,
        "posture": posture,
        "runs": runs,
        "path": path,
        "attempts": attempts,
        "q0": q0,
    }


def case_summary(case: Case, result: dict) -> tuple[dict, dict]:
    """The ``cases[key]`` entry of summary.json and the case's diagnostics (``details``)."""
    arm, runs, q0 = result["arm"], result["runs"], result["q0"]
    algs = {}
    for alg, run in runs.items():
        s = run.summary()
        algs[alg] = {
            k: s[k] for k in ("jvj_mean", "jvj_max", "rcn_mean", "rcn_max", "tracking_error_max")
        }
    J0 = arm.jacobian(q0)
    xd0 = result["path"].xdot(0.0)
    red = jump_reduction(J0, xd0, list(case.lockable), joint_names=arm.joint_names)
    extra = {
        "K0": result["posture"].K,
        "posture_method": result["posture"].method,
        "eq14_at_start": {"delta": red.delta, "f_qh2": red.predicted},
        "near_singular_samples": {a: r.summary()["near_singular_samples"] for a, r in runs.items()},
        "planning": {
            "rcn_threshold": RCN_THRESHOLD,
            "attempts": [
                {
                    "q0": a.q0.tolist(),
                    "K0": a.K0,
                    "rcn_max": a.rcn_max,
                    "accepted": a.accepted,
                    "reason": a.reason,
                }
                for a in result["attempts"]
            ],
        },
    }
    if arm.name == "spatial_4r":
        extra["N44_max"] = float(
            max(abs(projection(arm.jacobian(q)).N[3, 3]) for q in runs["jvja"].q[::10])
        )
    return {
        "robot": case.robot,
        "lockable": list(case.lockable),
        "x0": list(case.x0),
        "q0": q0.tolist(),
        "algorithms": algs,
    }, extra


def run_experiment(
    exp: LockExperiment = EXPERIMENT, *, duration: float | None = None, progress=None
) -> dict:
    """Sec. V: planned LNVA run, lock moments of largest / smallest jump, two lock runs."""
    arm = load_arm(exp.robot)
    T = duration or exp.duration
    posture = initial_posture(arm, np.array(exp.x0), [exp.joint])
    planned = simulate(
        arm,
        exp.path(T),
        "lnva",
        q0=posture.q,
        lockable=[exp.joint],
        progress=progress,
        limits=False,
    )
    t_max = float(planned.t[int(np.argmax(planned.jvj))])
    t_min = float(planned.t[int(np.argmin(planned.jvj))])
    runs = {}
    horizon = max(T, max(t_max, t_min) + exp.after_lock)
    if hasattr(progress, "grow"):  # the estimate assumed T + after_lock; correct it
        progress.grow(3 * (int(round(horizon / 1e-3)) - int(round((T + exp.after_lock) / 1e-3))))

    def lnva_run(**lock):
        return simulate(
            arm,
            exp.path(horizon),
            "lnva",
            q0=posture.q,
            lockable=[exp.joint],
            servo=exp.servo,
            feedback_gain=exp.feedback_gain,
            progress=progress,
            limits=False,
            **lock,
        )

    baseline = lnva_run()
    for label, t_lock in (("largest jump", t_max), ("smallest jump", t_min)):
        runs[label] = lnva_run(lock_joint=exp.joint, lock_time=t_lock)
    return {
        "arm": arm,
        "posture": posture,
        "planned": planned,
        "baseline": baseline,
        "runs": runs,
        "t_max": t_max,
        "t_min": t_min,
    }


def experiment_summary(exp: LockExperiment, result: dict) -> tuple[dict, dict]:
    """The ``experiment`` entry of summary.json and the experiment's diagnostics (``details``)."""
    runs, base = result["runs"], result["baseline"]

    def deviation(run: Run) -> float:
        after = run.t >= run.meta["lock"]["time"]
        return float(np.max(np.linalg.norm(run.x[after] - base.x[after], axis=1)))

    s_max, s_min = runs["largest jump"].summary(), runs["smallest jump"].summary()
    contract = {
        "robot": exp.robot,
        "joint": exp.joint,
        "t_max_jump": result["t_max"],
        "t_min_jump": result["t_min"],
        "path_error_peak_at_max": s_max["path_error_peak_after_lock"],
        "path_error_peak_at_min": s_min["path_error_peak_after_lock"],
        "servo_model": exp.servo.describe() + f"; task feedback K_p = {exp.feedback_gain} 1/s",
    }
    return contract, {
        "jump_at_max": float(np.max(result["planned"].jvj)),
        "jump_at_min": float(np.min(result["planned"].jvj)),
        "deviation_from_unlocked_at_max": deviation(runs["largest jump"]),
        "deviation_from_unlocked_at_min": deviation(runs["smallest jump"]),
        "path_error_max_without_lock": float(np.max(base.error)),
        "x0": list(exp.x0),
        "q0": result["posture"].q.tolist(),
        "paper_t_max_jump": exp.paper_t_max,
        "paper_t_min_jump": exp.paper_t_min,
    }


def eq8_check(duration: float | None = None) -> dict:
    """Eq. (8): only joint 3 of the planar 3R may lock → its JVJA rate and the jump stay zero."""
    case = CASES["fig2"]
    arm = load_arm(case.robot)
    posture = initial_posture(arm, np.array(case.x0), ["joint3"])
    run = simulate(
        arm, case.path(duration), "jvja", q0=posture.q, lockable=["joint3"], limits=False
    )
    return {
        "max_abs_rate_joint3": float(np.max(np.abs(run.qd[:, 2]))),
        "jvj_max": float(np.max(run.jvj)),
        "tracking_error_max": float(np.max(run.error)),
    }


def step_timing(repeats: int = 500) -> dict:
    """Mean time of one ``resolve`` call per algorithm on the planar 3R [µs] (plain path)."""
    from fault_tolerance.resolution.resolvers import resolve

    arm = load_arm("planar_3r")
    q = np.array([0.3, 1.2, 1.0])
    J, xd, dJ = arm.jacobian(q), np.array([0.1, 0.05]), arm.jacobian_derivatives(q)
    out = {}
    for alg in ALGORITHMS:
        t0 = time.perf_counter()
        for _ in range(repeats):
            resolve(alg, J, xd, None, dJ=dJ)
        out[alg] = 1e6 * (time.perf_counter() - t0) / repeats
    return out
