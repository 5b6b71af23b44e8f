"""``fault-tolerance simulate``: one task run per algorithm, files into ``--out``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fault_tolerance.cli.common import (
    EXIT_INTERRUPTED,
    FORMATTER,
    add_path_options,
    add_robot_options,
    bar,
    epilog,
    limits_line,
    load_robot,
    names,
    report_warnings,
    resolver_options,
)
from fault_tolerance.cli.dynamics_options import (
    add_dynamics_options,
    check_dynamics_args,
    dynamics_model,
)
from fault_tolerance.cli.start_options import choose_start, print_start
from fault_tolerance.errors import InvalidInput
from fault_tolerance.simulation.compare import compare_runs
from fault_tolerance.storage.atomic import to_json, write_atomic

NAME = "simulate"
HELP = "one task run with one or several algorithms"
EXAMPLE = (
    "fault-tolerance simulate --robot planar_3r --out out/fig2\n"
    "  fault-tolerance simulate --robot spatial_4r --x0 -0.21,0.20,0.35 --algorithms jvja,lnva --out out/4r\n"
    "  fault-tolerance simulate --robot spatial_4r --x0=-0.21,0.20,0.35 --algorithms lnva,jvja,global\n"
    "  fault-tolerance simulate --robot panda --task position --lockable panda_joint2,panda_joint4 "
    "--radius 0.05 --rows y,z --out out/panda\n"
    "  fault-tolerance simulate --robot panda --algorithms jvja --no-limits --out out/panda_paper\n"
    "  fault-tolerance simulate --description my_arm.urdf --tip tool --task position --lockable joint1,joint2,joint3 --csv path.csv --out out/mine"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``simulate`` sub-command."""
    from fault_tolerance.resolution.resolvers import BUILTINS
    from fault_tolerance.simulation.simulate import algorithms

    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    add_robot_options(s)
    add_path_options(s)
    s.add_argument(
        "--algorithms",
        default=",".join(e.name for e in BUILTINS),
        help=f"comma-separated among {','.join(algorithms())} (registered resolvers, then path "
        "planners; global: the whole-path plan, docs/MATH.md W1-W5; with --x0 and no --q0 it "
        "chooses its start on the self-motion of x0)",
    )
    add_plan_options(s)
    add_dynamics_options(s)
    s.add_argument(
        "--global-start",
        default="same",
        choices=["same", "free"],
        help="global: start from the same q0 as the other methods (default, a like-for-like "
        "table) or free on the self-motion of the path's start (the plan chooses it)",
    )
    s.add_argument(
        "--out", default=None, help="output folder (default: none, only the table is printed)"
    )
    s.add_argument(
        "--html", action="store_true", help="also write a self-contained replay.html per run"
    )
    s.add_argument(
        "--no-progress", action="store_true", help="no progress bar (default: the bar is shown)"
    )
    s.set_defaults(func=run)
    return s


def add_plan_options(s) -> None:
    """``--objective`` and ``--rcn-max`` of the global plan."""
    g = s.add_argument_group("global plan")
    g.add_argument(
        "--objective",
        default="mean",
        choices=["mean", "max"],
        help="what the global plan minimises: the mean (default) or the maximum of λ(t)",
    )
    g.add_argument(
        "--rcn-max",
        type=float,
        default=None,
        help="global plan: keep every reduced condition number k_S below this bound",
    )


def _algorithms(args) -> list[str]:
    from fault_tolerance.simulation.simulate import algorithms

    algs = names(args.algorithms) or []
    bad = [a for a in algs if a not in algorithms()]
    if bad or not algs:
        raise InvalidInput(f"--algorithms {args.algorithms!r}: choose among {list(algorithms())}")
    return algs


def _sim_options(args, algs: list[str]) -> tuple[dict, dict]:
    """The runs' shared options of :func:`simulate`, and ``--option`` (each algorithm its own)."""
    from fault_tolerance.resolution.mda import MDA_GAIN

    resolver = resolver_options(args, algs)  # an option none of algs takes is refused
    options = {
        "duration": args.duration,
        "feedback_gain": args.feedback or 0.0,
        "response": args.response,
        "gain": MDA_GAIN if args.gain is None else args.gain,
        "limits": not args.no_limits,  # the default start's checks run the same formulation
        "engine": first_run_engine(args, len(algs)),
    }
    if resolver:
        options["options"] = resolver
    return options, resolver


def _global_start(alg: str, args) -> dict:
    """For ``global``: its plan options, and a free start (q0=None) with ``--global-start free``.

    By default ``global`` starts where the other methods start, so that one table compares
    methods, not starts.
    """
    if alg != "global":
        return {}
    opts = {"objective": args.objective}
    if args.rcn_max is not None:
        opts["rcn_max"] = args.rcn_max
    extra: dict = {"plan_options": opts}
    if getattr(args, "global_start", "same") == "free":
        extra["q0"] = None  # free on the self-motion of the path's start: the plan chooses it
    return extra


def _check_global_start(args, algs) -> None:
    """``--global-start free`` needs ``global`` among the algorithms and no ``--q0``."""
    if getattr(args, "global_start", "same") != "free":
        return
    if "global" not in algs:
        raise InvalidInput(
            "--global-start free needs global among --algorithms (it sets global's start)"
        )
    if args.q0 is not None:
        raise InvalidInput(
            "--global-start free frees global's start; it cannot be combined with --q0"
        )


def run(args) -> int:
    """One task run per algorithm; files into --out (locked while written, each run whole)."""
    from fault_tolerance.storage.folder_io import check_path_names
    from fault_tolerance.storage.folder_lock import FolderLock

    check_dynamics_args(args)
    if not args.out:
        return _run(args, None)
    out = check_path_names(Path(args.out))
    with FolderLock(out):
        return _run(args, out)


#: Samples (all runs together) up to which a first run takes the reference engine rather than
#: compiling the fast path first (the reference does ~2000-5000 samples/s on the Panda).
SHORT_RUN = 60_000
#: What a first run with the reference engine says (one line on stderr).
REFERENCE_NOTICE = (
    "fault-tolerance: the compiled fast path is not in the cache yet; this run takes the "
    "reference engine (the same numbers to 1e-6); 'fault-tolerance warm' compiles the fast path "
    "once for the next runs"
)


#: The kernel groups a run of ``simulate`` or ``lock`` uses (:mod:`fault_tolerance.bench.warm`).
SIMULATE_KERNELS = ("controller", "bounded", "simulate")


def first_run_engine(args, runs: int) -> str:
    """``"auto"``, or ``"reference"`` for a short run while the fast path is not compiled yet.

    A long run (more than :data:`SHORT_RUN` samples) compiles the fast path first, saying so on
    one line of stderr; a short one takes the reference engine (then call
    :func:`announce_first_run` once the inputs are checked; docs/performance.md "First run").
    """
    from fault_tolerance.bench import warm

    if not warm.compile_ahead() or not warm.cold_groups(SIMULATE_KERNELS):
        return "auto"
    duration = args.duration if args.duration else 10.0  # the shipped paths are shorter
    if runs * duration / args.dt > SHORT_RUN:
        warm.warm(SIMULATE_KERNELS)
        return "auto"
    return "reference"


def announce_first_run(engine: str) -> None:
    """For a first run on the reference engine: one line on stderr saying how to warm the cache."""
    if engine == "reference":
        print(REFERENCE_NOTICE, file=sys.stderr)


def _run(args, out: Path | None) -> int:
    from fault_tolerance.resolution.registry import names as registered
    from fault_tolerance.resolution.scenarios import scenarios
    from fault_tolerance.simulation.diagnostics import check_run as check
    from fault_tolerance.simulation.setup import TRACKED_PAST_PLAN
    from fault_tolerance.simulation.simulate import options_for, simulate
    from fault_tolerance.storage.atomic import output_folder
    from fault_tolerance.storage.budget import check_run

    arm = load_robot(args)
    algs = _algorithms(args)
    _check_global_start(args, algs)
    options, resolver = _sim_options(args, algs)
    out = output_folder(out) if out else None
    stepwise = [a for a in algs if a in registered()] or [TRACKED_PAST_PLAN]  # checks the start
    q0, path, lockable, choice = choose_start(args, arm, stepwise, **options)
    checked = {} if choice is None or args.dynamics else choice.runs  # kinematic checks
    if args.dynamics:
        options["dynamics"] = dynamics_model(args)
    duration = args.duration or path.duration
    f = scenarios(lockable, arm.n, r=arm.redundancy, joint_names=arm.joint_names).f
    steps = check_run(args.dt, duration, arm.n, arm.m, f, runs=len(algs))  # all kept in memory
    print_start(args, arm, q0, choice)
    announce_first_run(options["engine"])
    progress = bar(steps * len(algs), not args.no_progress, "simulate")
    runs, saved, found = {}, [], {}
    try:
        for alg in algs:
            if alg in checked:
                runs[alg] = checked[alg]
                if progress:
                    progress.update(steps)
            else:
                runs[alg] = simulate(
                    arm,
                    path,
                    alg,
                    **{"q0": q0, **_global_start(alg, args)},
                    lockable=lockable,
                    dt=args.dt,
                    progress=progress,
                    **{**options, "options": options_for(alg, resolver)},
                )
            found[alg] = check(runs[alg], arm)
            if out:  # the run, its plot and page appear together, whole
                runs[alg].save(
                    out / alg,
                    extras=_extras(runs[alg], arm, args.html),
                    warnings=[w.as_dict() for w in found[alg]],
                )
                saved.append(alg)
    except KeyboardInterrupt:
        if progress:
            progress.close()
        done = saved if out else list(runs)
        print(
            f"interrupted: finished {done}, not finished {[a for a in algs if a not in done]}"
            + (f"; finished runs are in {out}" if out else ""),
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if progress:
        progress.close()
    _report(runs, arm, algs, out, args.dynamics)
    return 0


def _report(runs, arm, algs, out, dynamics: bool = False) -> None:
    """The table, its start and winner lines, warnings, and the comparison files in ``out``."""
    print_table(runs)
    if dynamics:
        print_dynamics_table(runs)
    comparison = compare_runs(runs)
    for line in comparison.lines() + _plan_lines(runs):
        print(line)
    for alg, run_ in runs.items():
        report_warnings(NAME, alg, run_, arm)
        print(f"{alg}: {limits_line(run_)}")
    if out:
        from fault_tolerance.figures import runs as plots
        from fault_tolerance.figures.text import plain

        title = plain(f"{arm.name}: {', '.join(algs)}")  # names are data, not mathtext
        plots.save_figure(plots.plot_comparison(runs, title), out / "comparison")
        write_atomic(out / "comparison.json", to_json(comparison.as_dict()))
        print(
            f"wrote {out}/ (run.npz, run.csv, summary.json per algorithm; comparison.png/.svg, "
            "comparison.json)"
        )


def _plan_lines(runs) -> list[str]:
    """What the global plan did, when it is not a plan of its own (``global.note`` of its meta)."""
    run_ = runs.get("global")
    note = (run_.meta.get("global") or {}).get("note") if run_ is not None else None
    return [f"global: {note}"] if note else []


def _extras(run_, arm, html: bool):
    """What :meth:`Run.save` adds to a run's folder: its plot, and its replay page if asked."""

    def write(folder: Path) -> None:
        from fault_tolerance.figures import runs as plots

        plots.save_figure(plots.plot_run(run_), folder / "run")
        if html:
            from fault_tolerance.viz.page import export_html

            export_html(run_, folder / "replay.html", arm=arm)

    return write


def print_dynamics_table(runs) -> None:
    """Peak torque and its ratio to the effort limit, per run of ``--dynamics``."""
    print(
        f"{'algorithm':13} {'peak |τ| [N·m]':>15} {'peak |τ|/τmax':>14} {'saturated samples':>18}"
    )
    for alg, run_ in runs.items():
        s = run_.summary()
        ratio = s["torque_peak_ratio"]
        print(
            f"{alg:13} {s['torque_max']:15.4g} {ratio if ratio is not None else float('nan'):14.3f} "
            f"{s['torque_saturated_samples']:18d}"
        )


def print_table(runs) -> None:
    """λ and K statistics, position error [m] (and orientation error [rad]) of each run."""
    summaries = {alg: run_.summary() for alg, run_ in runs.items()}
    angular = any("orientation_error_max" in s for s in summaries.values())
    w = max([10, *map(len, summaries)])  # a registered resolver's name may be longer
    print(
        f"{'algorithm':{w}} {'λ mean':>10} {'λ max':>10} {'K mean':>10} {'K max':>10} "
        f"{'pos err max [m]':>16}" + (f" {'ori err max [rad]':>18}" if angular else "")
        + "   (λ in (rad/s)²)"
    )  # fmt: skip
    for alg, s in summaries.items():
        ori = f" {s.get('orientation_error_max', float('nan')):18.3g}" if angular else ""
        print(
            f"{alg:{w}} {s['jvj_mean']:10.4g} {s['jvj_max']:10.4g} {s['rcn_mean']:10.4g} "
            f"{s['rcn_max']:10.4g} {s['tracking_error_max']:16.3g}" + ori
        )
