"""``reproduce``'s section "beyond the paper": the whole-path plan against the paper's planners.

For each of the paper's five cases the global plan (:mod:`.wholepath`) runs from the same start as
LNVA, JVJA and MDA (the case's minimum-RCN start); the Power-Cube lock experiment of Sec. V is
repeated with the global plan as the planned motion (the joint locks at the moments of the plan's
largest and smallest jump). The paper's own sections are left as they are: this section writes new
keys of ``summary.json`` (``beyond_the_paper``) and a section of ``REPORT.md``. Every run here is
the paper's formulation (``limits=False``), like the paper's sections it is compared with; the
plan keeps its own position-limit handling (``plan_options['limits']``).
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.simulation.compare import compare_runs
from fault_tolerance.simulation.run import Run
from fault_tolerance.simulation.simulate import simulate

#: The algorithms compared in the section, the global plan first.
COMPARED = ("global", "lnva", "jvja", "mda")


def _stats(run: Run, arm) -> dict:
    from fault_tolerance.model.joint_limits import outside_limits

    s = run.summary()
    return {
        k: s[k]
        for k in ("jvj_mean", "jvj_max", "rcn_mean", "rcn_max", "tracking_error_max")
        if k in s
    } | {
        "over_speed_samples": s.get("over_speed_samples", 0),
        "outside_position_limits_samples": int(
            np.count_nonzero(outside_limits(arm, run.q).any(axis=1))
        ),
    }


def case_global(case, result: dict, *, progress=None) -> tuple[Run, dict]:
    """The global plan of a case from the start LNVA / JVJA / MDA used; its summary entry."""
    arm, path, q0 = result["arm"], result["path"], result["q0"]
    run = simulate(
        arm, path, "global", q0=q0, lockable=list(case.lockable), progress=progress, limits=False
    )
    algs = {"global": _stats(run, arm)} | {a: _stats(r, arm) for a, r in result["runs"].items()}
    plan = run.meta["global"]
    best_local = min(algs[a]["jvj_mean"] for a in ("lnva", "jvja"))
    fair = compare_runs({"global": run, **result["runs"]}).as_dict()
    entry = {
        "q0": np.asarray(q0).tolist(),
        "algorithms": algs,
        "method": plan["method"],
        "warm_start": plan["warm_start"],
        "improvement_over_warm_start": plan["improvement"],
        "improvement_over_best_local": (best_local - algs["global"]["jvj_mean"]) / best_local,
        "smallest_mean_jump": min(algs, key=lambda a: algs[a]["jvj_mean"]),
        "same_start": fair["same_start"],
        "start_of": fair["start_of"],
        "winner_jvj_mean": fair["winner_jvj_mean"]["methods"],
        "winner_jvj_max": fair["winner_jvj_max"]["methods"],
        "seconds": plan.get("seconds"),
    }
    return run, entry


def experiment_global(exp, *, duration: float | None = None, progress=None) -> tuple[dict, dict]:
    """Sec. V with the global plan: the lock at its largest and smallest jump, servo model on."""
    from fault_tolerance.model.loading import load_arm
    from fault_tolerance.planning.posture import initial_posture

    arm = load_arm(exp.robot)
    T = duration or exp.duration
    q0 = initial_posture(arm, np.array(exp.x0), [exp.joint]).q
    common = {"q0": q0, "lockable": [exp.joint], "feedback_gain": exp.feedback_gain}
    common["limits"] = False  # the paper's formulation, like Sec. V's runs
    planned = simulate(arm, exp.path(T), "global", progress=progress, **common)
    flat = float(np.ptp(planned.jvj)) <= 1e-12 * max(1.0, float(np.max(planned.jvj)))
    if flat:  # λ ≡ const (eq. 8: a lone lockable joint is held still): lock at the paper's moments
        t_max, t_min = (t * T / exp.duration for t in (exp.paper_t_max, exp.paper_t_min))
    else:
        t_max = float(planned.t[int(np.argmax(planned.jvj))])
        t_min = float(planned.t[int(np.argmin(planned.jvj))])
    runs = {"planned": planned}
    for label, t_lock in (("largest jump", t_max), ("smallest jump", t_min)):
        runs[label] = simulate(
            arm,
            exp.path(T),
            "global",
            servo=exp.servo,
            lock_joint=exp.joint,
            lock_time=t_lock,
            progress=progress,
            **common,
        )
    lnva = simulate(arm, exp.path(T), "lnva", progress=progress, **common)
    entry = {
        "robot": exp.robot,
        "joint": exp.joint,
        "q0": q0.tolist(),
        "t_max_jump": t_max,
        "t_min_jump": t_min,
        "jump_at_max": float(np.max(planned.jvj)),
        "jump_at_min": float(np.min(planned.jvj)),
        "path_error_peak_at_max": runs["largest jump"].summary()["path_error_peak_after_lock"],
        "path_error_peak_at_min": runs["smallest jump"].summary()["path_error_peak_after_lock"],
        "jvj_mean": {"global": float(np.mean(planned.jvj)), "lnva": float(np.mean(lnva.jvj))},
        "jvj_max": {"global": float(np.max(planned.jvj)), "lnva": float(np.max(lnva.jvj))},
        "method": planned.meta["global"]["method"],
        "constant_jump": flat,
        "servo_model": exp.servo.describe() + f"; task feedback K_p = {exp.feedback_gain} 1/s",
    }
    return runs, entry


def _start_cell(e: dict) -> str:
    """``same q0`` or which start each method used (entries from before lack the key: ``—``)."""
    if "same_start" not in e:
        return "—"
    if e["same_start"]:
        return "same q0 for all"
    return ", ".join(f"{a}: {k}" for a, k in e["start_of"].items())


def _winner_cell(e: dict) -> str:
    if "winner_jvj_mean" not in e:
        return "—"
    return f"{'='.join(e['winner_jvj_mean'])} / {'='.join(e['winner_jvj_max'])}"


def report_section(beyond: dict) -> str:
    """The REPORT.md section "Beyond the paper: whole-path planning" (Markdown)."""
    lines = [
        "## Beyond the paper: whole-path planning",
        "",
        "Not a claim of the paper. The global plan (`--algorithms global`, docs/MATH.md (W1)-(W6)) "
        "minimises the mean jump over the whole path under the same task constraint, tracking and "
        "joint limits, from the same start as LNVA, JVJA and MDA. It is a local optimum, not a "
        "certificate: on these cases (at dt = 5 ms) it is within 1 % of an independent "
        "B-spline trajectory optimisation of the same objective, mean or max "
        "(tests/test_global_optimality.py). Mean / max λ [(rad/s)²], mean K; "
        "a * marks a run that leaves a joint's position limits or exceeds a velocity limit.",
        "",
        "| case | " + " | ".join(f"{a} mean λ / max λ / mean K" for a in COMPARED) + " | method "
        "| vs warm start | vs best local | start | winner mean λ / max λ |",
        "|---|" + "---|" * (len(COMPARED) + 5),
    ]
    for key, e in beyond.get("cases", {}).items():
        cells = []
        for a in COMPARED:
            s = e["algorithms"].get(a)
            out = s is not None and (
                s["over_speed_samples"] or s["outside_position_limits_samples"]
            )
            cells.append(
                "—"
                if s is None
                else f"{s['jvj_mean']:.4g} / {s['jvj_max']:.4g} / {s['rcn_mean']:.4g}"
                + "*" * bool(out)
            )
        lines.append(
            f"| {key} | "
            + " | ".join(cells)
            + f" | {e['method']} | {100 * e['improvement_over_warm_start']:.1f} % "
            f"| {100 * e['improvement_over_best_local']:.1f} % | {_start_cell(e)} "
            f"| {_winner_cell(e)} |"
        )
    cases = beyond.get("cases", {})
    if cases:
        wins = [k for k, e in cases.items() if e["smallest_mean_jump"] == "global"]
        lines += [
            "",
            f"The global plan has the smallest mean jump in {len(wins)} of {len(cases)} cases"
            + ("" if len(wins) == len(cases) else f" (not in {sorted(set(cases) - set(wins))})")
            + ".",
        ]
    exp = beyond.get("experiment")
    if exp:
        note = (
            " The plan's jump is constant (zero: with joint 3 the only lockable joint the plan holds "
            "it still, eq. (8)), so there is no largest or smallest moment; the lock happens at the "
            "paper's moments (scaled to the run's length) instead."
            if exp.get("constant_jump")
            else ""
        )
        lines += [
            "",
            "**Power-Cube lock with the global plan.**"
            + note
            + " "
            + (
                f"Joint 3 locks at t = {exp['t_max_jump']:.3f} s and t = {exp['t_min_jump']:.3f} s; "
                if exp.get("constant_jump")
                else f"Joint 3 locks at the plan's largest jump (t = {exp['t_max_jump']:.3f} s, "
                f"λ = {exp['jump_at_max']:.4g}) and smallest (t = {exp['t_min_jump']:.3f} s, "
                f"λ = {exp['jump_at_min']:.4g}); "
            )
            + "path-error peaks after the lock "
            f"{1e3 * exp['path_error_peak_at_max']:.3f} mm and {1e3 * exp['path_error_peak_at_min']:.3f} mm. "
            f"Mean jump of the planned motion: global {exp['jvj_mean']['global']:.4g}, "
            f"LNVA {exp['jvj_mean']['lnva']:.4g} (method: {exp['method']}; {exp['servo_model']}).",
        ]
    return "\n".join(lines) + "\n"
