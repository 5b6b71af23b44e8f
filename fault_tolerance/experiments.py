"""The paper's cases as data (docs/MATH.md's table) and the ``reproduce`` pipeline.

``reproduce(out)`` runs every case with LNVA, JVJA and MDA from the minimum-RCN start (Sec. III.D
step i), the Power-Cube lock experiment of Sec. V, and writes figures (PNG + SVG), the runs,
``summary.json`` (DESIGN.md's contract) and ``REPORT.md`` (claim by claim, with verdicts).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .arm import Arm
from .files import output_folder, write_atomic
from .linalg import projection
from .loading import load_arm
from .planner import MDA_GAIN, jump_reduction
from .posture import RCN_THRESHOLD, initial_posture, plan
from .results import check_path_names, in_progress
from .run import Run
from .simulation import ServoModel, simulate
from .trajectories import CirclePath

ALGORITHMS = ("lnva", "jvja", "mda")
#: Starts spread along the self-motion curves for the sensitivity check of claim 1.
SENSITIVITY_STARTS = 6


@dataclass(frozen=True)
class Case:
    """One comparison case of the paper's Sec. IV."""

    key: str
    robot: str
    lockable: tuple[str, ...]
    x0: tuple[float, ...]
    radius: float  # [m]
    omega: float  # [rad/s]
    rows: tuple[int, int]
    duration: float = 1.0
    sign: float = 1.0
    title: str = ""

    def path(self, duration: float | None = None) -> CirclePath:
        """The task path of the case."""
        return CirclePath(
            np.array(self.x0),
            self.radius,
            self.omega,
            duration or self.duration,
            rows=self.rows,
            sign=self.sign,
            name=self.key,
        )


ALL3 = ("joint1", "joint2", "joint3")
CASES: dict[str, Case] = {
    c.key: c
    for c in [
        Case(
            "fig2",
            "planar_3r",
            ALL3,
            (0.35, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 2 — planar 3R, all joints lockable, start (0.35, 0) m",
        ),
        Case(
            "fig3",
            "planar_3r",
            ALL3,
            (0.40, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 3 — planar 3R, all joints lockable, start (0.40, 0) m",
        ),
        Case(
            "fig4",
            "planar_3r",
            ("joint2", "joint3"),
            (0.35, 0.0),
            0.1,
            2 * np.pi,
            (0, 1),
            title="Fig. 4 — planar 3R, joints 2 and 3 lockable, start (0.35, 0) m",
        ),
        Case(
            "fig6",
            "spatial_4r",
            ALL3,
            (0.09, 0.21, 0.27),
            0.075,
            2 * np.pi,
            (1, 2),
            title="Fig. 6 — spatial 4R, joints 1-3 lockable, start (0.09, 0.21, 0.27) m",
        ),
        Case(
            "fig7",
            "spatial_4r",
            ALL3,
            (-0.21, 0.20, 0.35),
            0.075,
            2 * np.pi,
            (1, 2),
            title="Fig. 7 — spatial 4R, joints 1-3 lockable, start (-0.21, 0.20, 0.35) m",
        ),
    ]
}


@dataclass(frozen=True)
class LockExperiment:
    """The Power-Cube experiment of Sec. V: LNVA, joint 3 locks at the largest / smallest jump."""

    robot: str = "powercube_3r"
    joint: str = "joint3"
    #: The paper does not give the start; we pick a point well inside the workspace.
    x0: tuple[float, float] = (0.50, 0.0)
    radius: float = 0.1  # ẋ = [-(π/30) sin(πt/3), (π/30) cos(πt/3)]: radius 0.1 m, ω = π/3
    omega: float = np.pi / 3
    duration: float = 6.0
    after_lock: float = 1.5  # the lock runs go on at least this long after the lock [s]
    servo: ServoModel = field(default_factory=lambda: ServoModel(tau=0.05))
    feedback_gain: float = 10.0  # [1/s], in the planned run and after the lock alike
    paper_t_max: float = 3.1
    paper_t_min: float = 4.5

    def path(self, duration: float) -> CirclePath:
        """The Power-Cube task path (a circle travelled once in 6 s)."""
        return CirclePath(
            np.array(self.x0),
            self.radius,
            self.omega,
            duration,
            rows=(0, 1),
            sign=-1.0,
            name="powercube",
        )


EXPERIMENT = LockExperiment()


# -- running ---------------------------------------------------------------------------------


class _Progress:
    """A tqdm bar over all simulation steps (silent when disabled)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.bar = None
        if enabled:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit="step", desc="reproduce", leave=True)

    def update(self, k: int = 1) -> None:
        if self.bar is not None:
            self.bar.update(k)

    def grow(self, k: int) -> None:
        """Add ``k`` steps to the total once the work is known exactly."""
        if self.bar is not None:
            self.bar.total += k
            self.bar.refresh()

    def describe(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_description(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


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
        arm, exp.path(T), "lnva", q0=posture.q, lockable=[exp.joint], progress=progress,
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


def start_sensitivity(
    case: Case,
    result: dict,
    *,
    starts: int = SENSITIVITY_STARTS,
    duration: float | None = None,
    progress=None,
) -> dict:
    """Claim 1 from other starts: LNVA and JVJA from other dexterous points of the self-motion curves.

    The paper gives the start point but not the start posture, so the verdict on "JVJA's jump is
    smaller along the task" should not hang on our choice of posture. The starts are spread over
    the points of the self-motion curves whose K is in its lowest quartile (the starts a planner
    following Sec. III.D would consider; from near-singular starts every algorithm's λ is dominated
    by spikes), with angles wrapped into the joint limits; a start outside them is dropped, and a
    start whose LNVA or JVJA run meets a reduced condition number above
    :data:`~.posture.RCN_THRESHOLD` (Sec. III.D (iii)) is replaced by the next candidate, not
    counted (``replaced``). The runs are the paper's (no joint limits). Returns, per start, the
    time-mean λ of both algorithms, the diagnostics' warnings of their runs and the fraction of
    starts where JVJA's is the smaller. A counted start whose runs have warnings (over the velocity
    limit, near-singular, off the path) is *degenerate*: it is kept in ``starts`` with
    ``"degenerate": True`` and left out of the fraction.
    """
    from .diagnostics import check_run
    from .limits import outside_limits
    from .posture import wrap

    arm, path = result["arm"], case.path(duration)
    curves = result["posture"].curves
    if not curves:
        return {}
    points = np.concatenate(curves)
    K = np.concatenate(result["posture"].curve_K)  # with the case's lockable joints
    good = points[K <= np.quantile(K, 0.25)]  # the starts a Sec. III.D planner would consider
    good = np.array([wrap(arm, q) for q in good])  # angles wrapped into the joint limits
    good = good[~outside_limits(arm, good).any(axis=1)]
    spread = np.linspace(0, len(good) - 1, starts, endpoint=False).astype(int)
    order = list(spread) + [i for i in _stride_order(len(good)) if i not in set(spread)]
    rows, replaced = [], 0
    for i in order[: SENSITIVITY_TRIES * starts]:
        runs = {
            alg: simulate(
                arm, path, alg, q0=good[i], lockable=list(case.lockable), progress=progress,
                limits=False,
            )
            for alg in ("lnva", "jvja")
        }
        if max(float(np.max(r.rcn)) for r in runs.values()) > RCN_THRESHOLD:
            replaced += 1  # Sec. III.D (iii) would reject this start: replaced, not counted
            continue
        warned = [f"{alg}: {w.message}" for alg, r in runs.items() for w in check_run(r, arm)]
        rows.append(
            {
                "q0": good[i].tolist(),
                "jvj_mean_lnva": float(np.mean(runs["lnva"].jvj)),
                "jvj_mean_jvja": float(np.mean(runs["jvja"].jvj)),
                "degenerate": bool(warned),
                "warnings": warned,
            }
        )
        if len(rows) == starts:
            break
    kept = [r for r in rows if not r["degenerate"]]
    wins = sum(r["jvj_mean_jvja"] <= r["jvj_mean_lnva"] for r in kept)
    return {
        "starts": rows,
        "replaced": replaced,
        "jvja_smaller_fraction": wins / len(kept) if kept else None,
        "degenerate_starts": [i for i, r in enumerate(rows) if r["degenerate"]],
    }


#: Start-sensitivity candidates tried per start wanted (starts failing the RCN threshold are replaced).
SENSITIVITY_TRIES = 4


def _stride_order(count: int) -> list[int]:
    """Indices 0..count-1 in a spread-out order (golden-ratio strides)."""
    return list(np.argsort((np.arange(count) * 0.6180339887498949) % 1.0))


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
    from .planner import resolve

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


# -- the pipeline ------------------------------------------------------------------------------


def _warn(summary: dict, name: str, run, arm) -> list[dict]:
    """The diagnostics' warnings of one reproduced run, also listed in ``summary["warnings"]``."""
    from .diagnostics import check_run

    found = [w.as_dict() for w in check_run(run, arm)]
    summary["warnings"] += [{"run": name, **w} for w in found]
    return found


def reproduce(
    out: str | Path,
    *,
    cases: list[str] | None = None,
    quick: bool = False,
    progress: bool = True,
    html: bool = False,
    beyond: bool = True,
) -> dict:
    """Every case of the paper into ``out``: figures, runs, ``summary.json``, ``REPORT.md``.

    Args:
        out: Output folder (created).
        cases: Subset of case keys (default all, plus the lock experiment ``"experiment"``).
        quick: Shorter runs (0.25 s cases, 3 s experiment) for tests; the report says so.
        progress: Show a progress bar.
        html: Also write a self-contained meshcat replay (``replay.html``) for each JVJA run.
        beyond: Also the section "beyond the paper" (:mod:`.beyond`): the whole-path plan against
            LNVA, JVJA and MDA on every case and in the lock experiment (``beyond_the_paper`` in
            summary.json, its own section of REPORT.md, figures ``beyond_*``).

    On Ctrl-C (or an error) the cases already finished stay on disk, ``summary.partial.json``
    lists what was and was not finished and what stopped the run, an existing ``summary.json`` is
    left as it was, and the exception is raised again.
    """
    keys = _case_keys(cases)
    check_path_names(out)
    with in_progress(out):  # locked, and marked in progress until summary.json is final
        return _reproduce(output_folder(out), keys, quick, progress, html, beyond)


def _case_keys(cases: list[str] | None) -> list[str]:
    """The cases to run (all when None); an empty list or an unknown name is refused."""
    from .errors import InvalidInput

    keys = list(CASES) + ["experiment"] if cases is None else list(cases)
    unknown = [k for k in keys if k not in CASES and k != "experiment"]
    allowed = list(CASES) + ["experiment"]
    if unknown:
        raise InvalidInput(f"unknown case(s) {unknown}; choose among {allowed}")
    if not keys or len(set(keys)) != len(keys):
        raise InvalidInput(f"case list {keys}: name each case once, among {allowed}")
    return keys


def _reproduce(
    out: Path, keys: list[str], quick: bool, progress: bool, html: bool, beyond: bool
) -> dict:
    from . import plots

    case_T = 0.25 if quick else None
    exp_T = 3.0 if quick else None
    total = sum(  # three algorithms, then LNVA and JVJA from the other starts
        (3 + 2 * SENSITIVITY_STARTS) * (int(round((case_T or CASES[k].duration) / 1e-3)) + 1)
        for k in keys
        if k in CASES
    )
    if "experiment" in keys:
        T = exp_T or EXPERIMENT.duration
        total += int(round(T / 1e-3)) + 1 + 3 * (int(round((T + EXPERIMENT.after_lock) / 1e-3)) + 1)
    bar = _Progress(total, progress)
    summary: dict = {"cases": {}, "experiment": {}, "details": {}, "warnings": []}
    if beyond:
        summary["beyond_the_paper"] = {"cases": {}}
    done: list[str] = []
    results: dict = {}  # the cases' runs, for the section beyond the paper
    started = time.perf_counter()
    try:
        for key in keys:
            bar.describe(key)
            if key == "experiment":
                res = run_experiment(duration=exp_T, progress=bar)
                summary["experiment"], summary["details"]["experiment"] = experiment_summary(
                    EXPERIMENT, res
                )
                fig = plots.plot_lock(
                    res["runs"],
                    "Figs. 9-10 — Power-Cube 3R, LNVA, joint 3 locks "
                    "at the largest / smallest jump",
                    planned=res["planned"],
                )
                plots.save_figure(fig, out / "fig9_10")
                for label, run in res["runs"].items():
                    name = f"experiment/{label.replace(' ', '_')}"
                    page = html and label == "largest jump"
                    run.save(
                        out / "runs" / name,
                        extras=_html(run, res["arm"]) if page else None,
                        warnings=_warn(summary, name, run, res["arm"]),
                    )
                res["planned"].save(
                    out / "runs" / "experiment" / "planned",
                    warnings=_warn(summary, "experiment/planned", res["planned"], res["arm"]),
                )
            else:
                case = CASES[key]
                res = run_case(case, duration=case_T, progress=bar)
                summary["cases"][key], summary["details"][key] = case_summary(case, res)
                summary["details"][key]["start_sensitivity"] = start_sensitivity(
                    case, res, duration=case_T, progress=bar
                )
                plots.save_figure(plots.plot_comparison(res["runs"], case.title), out / key)
                for alg, run in res["runs"].items():
                    page = html and alg == "jvja"
                    run.save(
                        out / "runs" / key / alg,
                        extras=_html(run, res["arm"]) if page else None,
                        warnings=_warn(summary, f"{key}/{alg}", run, res["arm"]),
                    )
                if beyond:
                    results[key] = res
            done.append(key)
        summary["checks"] = {"eq8": eq8_check(case_T), "step_time_us": step_timing()}
        done.append("checks")
        if beyond:  # after the paper's own sections, which are complete by now
            bar.describe("beyond the paper")
            for key, res in results.items():
                _beyond_case(summary, out, CASES[key], res, bar)
            if "experiment" in keys:
                _beyond_experiment(summary, out, exp_T, bar)
            done.append("beyond_the_paper")
    except BaseException as err:  # Ctrl-C or a failure: keep what is done, say what is not
        bar.close()
        partial = {
            "stopped_by": "interrupted (Ctrl-C)"
            if isinstance(err, KeyboardInterrupt)
            else f"{type(err).__name__}: {err}",
            "finished": [k for k in done if k in keys],
            "unfinished": [k for k in keys if k not in done]
            + ([] if "checks" in done else ["checks"]),
            "beyond_the_paper_finished": "beyond_the_paper" in done if beyond else None,
            **summary,
        }
        write_atomic(
            out / "summary.partial.json", json.dumps(partial, indent=2, default=str) + "\n"
        )
        raise
    bar.close()
    summary["meta"] = {
        "quick": quick,
        "seconds": round(time.perf_counter() - started, 2),
        "algorithms": list(ALGORITHMS),
        "dt": 1e-3,
        "mda_gain": MDA_GAIN,
    }
    write_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    from .report import write_report

    report = write_report(summary)
    if beyond:
        from .beyond import report_section

        report = report.rstrip("\n") + "\n\n" + report_section(summary["beyond_the_paper"])
    write_atomic(out / "REPORT.md", report)
    partial = out / "summary.partial.json"
    if partial.exists():
        partial.unlink()
    return summary


def _beyond_case(summary: dict, out: Path, case: Case, res: dict, bar) -> None:
    """The global plan of one case from the same start, saved beside the paper's runs."""
    from . import plots
    from .beyond import case_global

    if hasattr(bar, "grow"):
        bar.grow(len(res["runs"]["jvja"].t))
    run, entry = case_global(case, res, progress=bar)
    summary["beyond_the_paper"]["cases"][case.key] = entry
    run.save(out / "runs" / case.key / "global")
    runs = {"global": run, **res["runs"]}
    plots.save_figure(plots.plot_comparison(runs, case.title + " — with the global plan"), out / f"beyond_{case.key}")


def _beyond_experiment(summary: dict, out: Path, duration, bar) -> None:
    """The Power-Cube lock experiment with the global plan."""
    from . import plots
    from .beyond import experiment_global

    runs, entry = experiment_global(EXPERIMENT, duration=duration, progress=bar)
    summary["beyond_the_paper"]["experiment"] = entry
    for label, run in runs.items():
        run.save(out / "runs" / "experiment_global" / label.replace(" ", "_"))
    locks = {k: v for k, v in runs.items() if k != "planned"}
    fig = plots.plot_lock(locks, "Power-Cube 3R, global plan, joint 3 locks")
    plots.save_figure(fig, out / "beyond_fig9_10")


def _html(run: Run, arm: Arm):
    """``extras`` for :meth:`Run.save`: the run's replay page, written with the run."""

    def write(folder: Path) -> None:
        from .viz import export_html

        export_html(run, folder / "replay.html", arm=arm)

    return write
