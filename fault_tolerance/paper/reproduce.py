"""The ``reproduce`` pipeline: every case of the paper into one folder, with a report.

``reproduce(out)`` runs every case of :mod:`.paper_cases` with LNVA, JVJA and MDA from the
minimum-RCN start (Sec. III.D step i, :mod:`.paper_runs`), the start-sensitivity check of claim 1
(:mod:`.sensitivity`), the Power-Cube lock experiment of Sec. V, and writes figures (PNG + SVG),
the runs, ``summary.json`` (DESIGN.md's contract) and ``REPORT.md`` (claim by claim, with
verdicts, :mod:`.report`). The cases and runs are importable from here as before.

The way through: :mod:`.paper_cases` (what to run) -> :mod:`.paper_runs` (the runs and their
summary entries) -> this module (the folder) -> :mod:`.report` (the verdicts).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from fault_tolerance.model.arm import Arm
from fault_tolerance.paper.cases import ALGORITHMS, CASES, EXPERIMENT, Case
from fault_tolerance.paper.runs import (
    case_summary,
    eq8_check,
    experiment_summary,
    run_case,
    run_experiment,
    step_timing,
)
from fault_tolerance.paper.start_sensitivity import (
    SENSITIVITY_STARTS,
    start_sensitivity,
)
from fault_tolerance.paper.synthesis import report_section as synthesis_section
from fault_tolerance.paper.synthesis import synthesis
from fault_tolerance.resolution.mda import MDA_GAIN
from fault_tolerance.simulation.run import Run
from fault_tolerance.storage.atomic import output_folder, write_atomic
from fault_tolerance.storage.folder_io import check_path_names
from fault_tolerance.storage.folder_lock import in_progress

__all__ = [
    "reproduce",
]


# -- progress --------------------------------------------------------------------------------


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


# -- the pipeline ------------------------------------------------------------------------------


def _warn(summary: dict, name: str, run, arm) -> list[dict]:
    """The diagnostics' warnings of one reproduced run, also listed in ``summary["warnings"]``."""
    from fault_tolerance.simulation.diagnostics import check_run

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
            summary.json, its own section of REPORT.md, figures ``beyond_*``), and "The lock at
            torque level" (:mod:`.torque_level`, ``torque_level`` in summary.json).

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
    from fault_tolerance.errors import InvalidInput

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
    """The pipeline inside the folder lock: the paper's sections, the checks, beyond, the files."""
    case_T = 0.25 if quick else None
    exp_T = 3.0 if quick else None
    bar = _Progress(_total_steps(keys, case_T, exp_T), progress)
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
                _reproduce_experiment(summary, out, exp_T, bar, html)
            else:
                res = _reproduce_case(summary, out, CASES[key], case_T, bar, html)
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
            if "fig6" in keys and not quick:  # the DH synthesis the paper proposed, on its 4R
                bar.describe("synthesis")
                summary["beyond_the_paper"]["synthesis"] = synthesis(out)
            done.append("beyond_the_paper")
            _torque_level(summary, bar, quick)
            done.append("torque_level")
    except BaseException as err:  # Ctrl-C or a failure: keep what is done, say what is not
        bar.close()
        _write_partial(out, summary, err, keys, done, beyond)
        raise
    bar.close()
    summary["meta"] = {
        "quick": quick,
        "seconds": round(time.perf_counter() - started, 2),
        "algorithms": list(ALGORITHMS),
        "dt": 1e-3,
        "mda_gain": MDA_GAIN,
    }
    _write_results(out, summary, beyond)
    return summary


def _total_steps(keys: list[str], case_T: float | None, exp_T: float | None) -> int:
    """Simulation steps of the whole pipeline (the progress bar's first estimate)."""
    total = sum(  # three algorithms, then LNVA and JVJA from the other starts
        (3 + 2 * SENSITIVITY_STARTS) * (int(round((case_T or CASES[k].duration) / 1e-3)) + 1)
        for k in keys
        if k in CASES
    )
    if "experiment" in keys:
        T = exp_T or EXPERIMENT.duration
        total += int(round(T / 1e-3)) + 1 + 3 * (int(round((T + EXPERIMENT.after_lock) / 1e-3)) + 1)
    return total


def _reproduce_experiment(summary: dict, out: Path, exp_T, bar, html: bool) -> None:
    """The Sec. V lock experiment: its summary entries, Figs. 9-10 and its runs."""
    from fault_tolerance.figures import runs as plots

    res = run_experiment(duration=exp_T, progress=bar)
    summary["experiment"], summary["details"]["experiment"] = experiment_summary(EXPERIMENT, res)
    fig = plots.plot_lock(
        res["runs"],
        "Figs. 9-10 — Power-Cube 3R, LNVA, joint 3 locks at the largest / smallest jump",
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


def _reproduce_case(summary: dict, out: Path, case: Case, case_T, bar, html: bool) -> dict:
    """One case of Sec. IV: its summary entries, start sensitivity, figure and runs."""
    from fault_tolerance.figures import runs as plots

    key = case.key
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
    return res


def _write_partial(
    out: Path, summary: dict, err: BaseException, keys: list[str], done: list[str], beyond: bool
) -> None:
    """``summary.partial.json``: what was finished, what was not, and what stopped the run."""
    partial = {
        "stopped_by": "interrupted (Ctrl-C)"
        if isinstance(err, KeyboardInterrupt)
        else f"{type(err).__name__}: {err}",
        "finished": [k for k in done if k in keys],
        "unfinished": [k for k in keys if k not in done] + ([] if "checks" in done else ["checks"]),
        "beyond_the_paper_finished": "beyond_the_paper" in done if beyond else None,
        **summary,
    }
    write_atomic(out / "summary.partial.json", json.dumps(partial, indent=2, default=str) + "\n")


def _write_results(out: Path, summary: dict, beyond: bool) -> None:
    """``summary.json``, then ``REPORT.md`` from it; a stale ``summary.partial.json`` goes."""
    write_atomic(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    from fault_tolerance.paper.report import write_report

    report = write_report(summary)
    if beyond:
        from fault_tolerance.paper.beyond_the_paper import report_section

        report = report.rstrip("\n") + "\n\n" + report_section(summary["beyond_the_paper"])
        if "synthesis" in summary["beyond_the_paper"]:
            report += "\n\n" + synthesis_section(summary["beyond_the_paper"]["synthesis"])
    if "torque_level" in summary:
        from fault_tolerance.paper import torque_level

        report = report.rstrip("\n") + "\n\n" + torque_level.report_section(summary["torque_level"])
    write_atomic(out / "REPORT.md", report)
    partial = out / "summary.partial.json"
    if partial.exists():
        partial.unlink()


def _torque_level(summary: dict, bar, quick: bool) -> None:
    """REPORT.md's "The lock at torque level" (:mod:`.torque_level`; quick: the Fig. 2 arm only)."""
    from fault_tolerance.paper.torque_level import torque_level

    bar.describe("the lock at torque level")
    summary["torque_level"] = torque_level(["fig2"] if quick else None)


def _beyond_case(summary: dict, out: Path, case: Case, res: dict, bar) -> None:
    """The global plan of one case from the same start, saved beside the paper's runs."""
    from fault_tolerance.figures import runs as plots
    from fault_tolerance.paper.beyond_the_paper import case_global

    if hasattr(bar, "grow"):
        bar.grow(len(res["runs"]["jvja"].t))
    run, entry = case_global(case, res, progress=bar)
    summary["beyond_the_paper"]["cases"][case.key] = entry
    run.save(out / "runs" / case.key / "global")
    runs = {"global": run, **res["runs"]}
    plots.save_figure(
        plots.plot_comparison(runs, case.title + " — with the global plan"),
        out / f"beyond_{case.key}",
    )


def _beyond_experiment(summary: dict, out: Path, duration, bar) -> None:
    """The Power-Cube lock experiment with the global plan."""
    from fault_tolerance.figures import runs as plots
    from fault_tolerance.paper.beyond_the_paper import experiment_global

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
        from fault_tolerance.viz.page import export_html

        export_html(run, folder / "replay.html", arm=arm)

    return write
