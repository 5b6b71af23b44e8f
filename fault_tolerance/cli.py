"""The ``fault-tolerance`` command.

Exit codes: 0 success, 2 bad input (one line on stderr naming the problem and what is allowed;
``--debug`` shows the traceback), 1 unexpected failure, 130 interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np

from . import __version__
from .errors import FaultToleranceError, InvalidInput

EXAMPLES = {
    "robots": "fault-tolerance robots",
    "inspect": "fault-tolerance inspect spatial_4r\n  fault-tolerance inspect my_arm.urdf --tip tool0",
    "simulate": (
        "fault-tolerance simulate --robot planar_3r --out out/fig2\n"
        "  fault-tolerance simulate --robot spatial_4r --x0 -0.21,0.20,0.35 --algorithms jvja,lnva --out out/4r\n"
        "  fault-tolerance simulate --robot panda --task position --lockable panda_joint2,panda_joint4 "
        "--radius 0.05 --rows y,z --out out/panda\n"
        "  fault-tolerance simulate --urdf my_arm.urdf --tip tool0 --task position --csv path.csv --out out/mine"
    ),
    "lock": (
        "fault-tolerance lock --robot powercube_3r --joint joint3 --at max --out out/lock_max\n"
        "  fault-tolerance lock --robot planar_3r --joint joint2 --at 0.4 --tau 0.02 --out out/lock"
    ),
    "reproduce": "fault-tolerance reproduce --out reproduce_out\n  fault-tolerance reproduce --out quick --quick --cases fig2,experiment",
    "replay": "fault-tolerance replay out/fig2/jvja --html replay.html\n  fault-tolerance replay out/fig2/jvja --open",
    "bench": "fault-tolerance bench\n  fault-tolerance bench --json new.json\n  fault-tolerance bench --compare old.json new.json",
}


def _epilog(cmd: str) -> str:
    return "example:\n  " + EXAMPLES[cmd]


def _floats(text: str, what: str) -> np.ndarray:
    try:
        vals = np.array([float(v) for v in text.replace(" ", "").split(",") if v != ""])
    except ValueError:
        raise InvalidInput(f"{what} must be comma-separated numbers, got '{text}'") from None
    if not len(vals) or not np.all(np.isfinite(vals)):
        raise InvalidInput(f"{what} must be finite comma-separated numbers, got '{text}'")
    return vals


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    return [t.strip() for t in text.split(",") if t.strip()]


# -- common robot options -------------------------------------------------------------------


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """``--robot | --urdf PATH [--package-dir DIR]``, ``--tip``, ``--task``, ``--joints``, ``--lockable``."""
    g = p.add_argument_group("robot")
    src = g.add_mutually_exclusive_group()
    src.add_argument(
        "--robot",
        default=None,
        help="shipped or example-robot-data arm (see `fault-tolerance robots`)",
    )
    src.add_argument("--urdf", default=None, help="path of a URDF file")
    g.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="folder for package:// meshes (repeatable)",
    )
    g.add_argument(
        "--tip", default=None, help="tip frame (default: the catalog's, or the last frame)"
    )
    g.add_argument(
        "--task", default=None, help="planar | position | pose | rows among x,y,z,rx,ry,rz"
    )
    g.add_argument("--joints", default=None, help="active joints, comma-separated (others fixed)")
    g.add_argument(
        "--lockable",
        default=None,
        help="joints that may lock: all | joint2,joint3 | joint1+joint2,joint3 (+ joins a multi-joint scenario)",
    )


def load_robot(args) -> object:
    """The arm the robot options describe."""
    from .loading import load_arm

    if args.robot is None and args.urdf is None:
        raise InvalidInput(
            "name a robot with --robot NAME or --urdf PATH (see `fault-tolerance robots`)"
        )
    return load_arm(
        args.urdf or args.robot,
        tip=args.tip,
        task=args.task,
        joints=_names(args.joints),
        package_dirs=args.package_dir or None,
    )


def lockable_of(args, arm):
    """Lockable joints from ``--lockable`` (``a+b`` is a two-joint scenario); arm default if absent."""
    if args.lockable is None:
        return list(arm.default_lockable)
    if args.lockable.strip() == "all":
        return list(arm.joint_names)
    items = []
    for tok in _names(args.lockable) or []:
        items.append(tuple(tok.split("+")) if "+" in tok else tok)
    if not items:
        raise InvalidInput("--lockable is empty; use 'all' or joint names like joint2,joint3")
    return items


# -- start, path ----------------------------------------------------------------------------


def add_path_options(p: argparse.ArgumentParser) -> None:
    """Start (``--x0`` / ``--q0``), path (circle or ``--csv``), time step and duration."""
    g = p.add_argument_group("start and path")
    g.add_argument(
        "--x0",
        default=None,
        help="start point (task coordinates); the start posture is the minimum-RCN one",
    )
    g.add_argument("--q0", default=None, help="start configuration (rad), used as given")
    g.add_argument(
        "--csv", default=None, help="task path from a CSV file with header t,x,y[,z...] [,vx,vy...]"
    )
    g.add_argument(
        "--radius",
        type=float,
        default=None,
        help="circle radius [m] (default: the paper's for shipped arms, else 0.05)",
    )
    g.add_argument(
        "--omega", type=float, default=None, help="circle angular rate [rad/s] (default 2π)"
    )
    g.add_argument(
        "--rows", default=None, help="the two task rows the circle lies in, e.g. x,y or y,z"
    )
    g.add_argument("--dt", type=float, default=1e-3, help="time step [s] (default 0.001)")
    g.add_argument(
        "--duration", type=float, default=None, help="run length [s] (default: the path's)"
    )
    g.add_argument(
        "--feedback", type=float, default=None, help="task-space feedback gain K_p [1/s]"
    )
    g.add_argument(
        "--response",
        default="least_norm",
        choices=["least_norm", "continuation"],
        help="post-failure response of the reduced robot (MATH.md G3)",
    )
    g.add_argument("--gain", type=float, default=None, help="MDA gain α (default planner.MDA_GAIN)")


def start_and_path(args, arm):
    """``(q0, path)`` from the options (posture search when only ``x0`` is known)."""
    from .catalog import catalog
    from .posture import initial_posture
    from .trajectories import CirclePath, load_csv

    entry = catalog().get(arm.name) if arm.source == arm.name else None
    if not (np.isfinite(args.dt) and args.dt > 0):
        raise InvalidInput(f"--dt must be a finite number > 0 [s], got {args.dt}")
    if args.duration is not None and not (np.isfinite(args.duration) and args.duration > 0):
        raise InvalidInput(f"--duration must be a finite number > 0 [s], got {args.duration}")
    lockable = lockable_of(args, arm)
    q0 = None if args.q0 is None else arm.check_q(_floats(args.q0, "--q0"))
    if args.csv:
        path = load_csv(args.csv, rows=list(arm.task) if len(arm.task) else None)
        x0 = path.x0
    else:
        if args.x0 is not None:
            x0 = _floats(args.x0, "--x0")
        elif q0 is not None:
            x0 = arm.fk(q0)
        elif entry and "x0" in entry:
            x0 = np.array(entry["x0"], dtype=float)
        else:
            q0 = arm.q_reference
            x0 = arm.fk(q0)
        if len(x0) != arm.m:
            raise InvalidInput(
                f"--x0 has {len(x0)} numbers; task {'/'.join(arm.task)} needs {arm.m}"
            )
        spec = (entry or {}).get("path", {})
        if args.rows:
            names = _names(args.rows) or []
            if len(names) != 2 or any(r not in arm.task for r in names) or names[0] == names[1]:
                raise InvalidInput(
                    f"--rows must name two different task rows among {list(arm.task)}, got '{args.rows}'"
                )
            rows = (arm.task.index(names[0]), arm.task.index(names[1]))
        else:
            rows = tuple(spec.get("rows", (0, 1) if arm.m >= 2 else (0, 0)))
        if arm.m < 2:
            raise InvalidInput("a circle needs at least two task rows; give a path with --csv")
        radius = args.radius if args.radius is not None else spec.get("radius", 0.05)
        omega = args.omega if args.omega is not None else spec.get("omega", 2 * np.pi)
        duration = spec.get("duration", 1.0)
        path = CirclePath(
            x0, radius, omega, args.duration or duration, rows=rows, sign=spec.get("sign", 1.0)
        )
    if q0 is None:
        q0 = initial_posture(arm, x0, lockable).q
    elif np.linalg.norm(arm.task_error(x0, q0)) > 1e-6:
        raise InvalidInput(
            f"--q0 puts the tool at {arm.fk(q0).round(4).tolist()}, not at the path's start {np.round(x0, 4).tolist()}"
        )
    return q0, path, lockable


def _bar(total: int, enabled: bool, desc: str):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="step", desc=desc)


# -- commands -------------------------------------------------------------------------------


def cmd_robots(args) -> int:
    """List shipped and example-robot-data arms."""
    from .catalog import EXAMPLE_ROBOTS, catalog
    from .loading import load_arm

    rows = []
    for name, entry in catalog().items():
        arm = load_arm(name)
        rows.append(
            (
                name,
                "shipped",
                arm.n,
                "/".join(arm.task),
                arm.m,
                arm.redundancy,
                entry["description"],
            )
        )
    for name, preset in EXAMPLE_ROBOTS.items():
        try:
            arm = load_arm(name)
        except FaultToleranceError as err:  # pragma: no cover - depends on the installed data
            rows.append((name, "example-robot-data", "?", "?", "?", "?", f"unavailable: {err}"))
            continue
        rows.append(
            (
                name,
                "example-robot-data",
                arm.n,
                "/".join(arm.task),
                arm.m,
                arm.redundancy,
                preset["description"],
            )
        )
    head = ("name", "source", "DOF", "task", "m", "r", "description")
    widths = [max(len(str(r[i])) for r in rows + [head]) for i in range(len(head))]
    for r in [head] + rows:
        print("  ".join(str(v).ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    print(
        "\nAny other example-robot-data name or a URDF path works too (--robot NAME | --urdf PATH)."
    )
    return 0


def cmd_inspect(args) -> int:
    """Print the kinematic tree, the chosen chain and task, and intolerable joints."""
    from .inspection import inspect_text

    print(
        inspect_text(
            args.target,
            tip=args.tip,
            task=args.task,
            joints=_names(args.joints),
            package_dirs=args.package_dir or None,
        )
    )
    return 0


def cmd_simulate(args) -> int:
    """One task run per algorithm; files into --out."""
    from .simulation import output_folder, simulate

    arm = load_robot(args)
    q0, path, lockable = start_and_path(args, arm)
    algs = _names(args.algorithms) or []
    from .planner import MDA_GAIN, RESOLVERS

    bad = [a for a in algs if a not in RESOLVERS]
    if bad or not algs:
        raise InvalidInput(f"--algorithms {args.algorithms!r}: choose among {sorted(RESOLVERS)}")
    out = output_folder(args.out) if args.out else None
    steps = int(round((args.duration or path.duration) / args.dt)) + 1
    bar = _bar(steps * len(algs), not args.no_progress, "simulate")
    runs, saved = {}, []
    try:
        for alg in algs:
            runs[alg] = simulate(
                arm,
                path,
                alg,
                q0=q0,
                lockable=lockable,
                dt=args.dt,
                duration=args.duration,
                feedback_gain=args.feedback or 0.0,
                response=args.response,
                gain=MDA_GAIN if args.gain is None else args.gain,
                progress=bar,
            )
            if out:
                runs[alg].save(out / alg)
                saved.append(alg)
    except KeyboardInterrupt:
        if bar:
            bar.close()
        done = saved if out else list(runs)
        print(
            f"interrupted: finished {done}, not finished {[a for a in algs if a not in done]}"
            + (f"; finished runs are in {out}" if out else ""),
            file=sys.stderr,
        )
        return 130
    if bar:
        bar.close()
    _print_table(runs)
    if out:
        from . import plots

        plots.save_figure(
            plots.plot_comparison(runs, f"{arm.name}: {', '.join(algs)}"), out / "comparison"
        )
        for alg, run in runs.items():
            plots.save_figure(plots.plot_run(run), out / alg / "run")
            if args.html:
                from .viz import export_html

                export_html(run, out / alg / "replay.html", arm=arm)
        print(f"wrote {out}/ (run.npz, run.csv, summary.json per algorithm; comparison.png/.svg)")
    return 0


def _print_table(runs) -> None:
    print(
        f"{'algorithm':10} {'λ mean':>10} {'λ max':>10} {'K mean':>10} {'K max':>10} {'track err max [m]':>18}"
    )
    for alg, run in runs.items():
        s = run.summary()
        print(
            f"{alg:10} {s['jvj_mean']:10.4g} {s['jvj_max']:10.4g} {s['rcn_mean']:10.4g} "
            f"{s['rcn_max']:10.4g} {s['tracking_error_max']:18.3g}"
        )


def cmd_lock(args) -> int:
    """A run in which a joint locks (at a time, or at the largest / smallest jump)."""
    from .simulation import ServoModel, output_folder, simulate

    arm = load_robot(args)
    q0, path, lockable = start_and_path(args, arm)
    joint = arm.joint_names[arm.joint_index(args.joint)]
    servo = ServoModel(tau=args.tau, accel_limit=args.accel_limit)
    if args.out:
        output_folder(args.out)  # refuse a bad --out before the runs
    feedback = 10.0 if args.feedback is None else args.feedback
    gain = {} if args.gain is None else {"gain": args.gain}
    duration = args.duration or path.duration
    if args.at in ("max", "min"):
        planned = simulate(
            arm,
            path,
            args.algorithm,
            q0=q0,
            lockable=[joint],
            dt=args.dt,
            duration=duration,
            response=args.response,
            **gain,
        )
        k = int(np.argmax(planned.jvj) if args.at == "max" else np.argmin(planned.jvj))
        t_lock = float(planned.t[k])
        print(
            f"{args.at} jump of {joint} in the planned run at t = {t_lock:.3f} s (λ = {planned.jvj[k]:.4g})"
        )
    else:
        t_lock = float(_floats(args.at, "--at")[0])
    bar = _bar(int(round(duration / args.dt)) + 1, not args.no_progress, "lock")
    run = simulate(
        arm,
        path,
        args.algorithm,
        q0=q0,
        lockable=lockable,
        dt=args.dt,
        duration=duration,
        lock_joint=joint,
        lock_time=t_lock,
        servo=servo,
        feedback_gain=feedback,
        response=args.response,
        progress=bar,
        **gain,
    )
    if bar:
        bar.close()
    s = run.summary()
    print(f"{joint} locks at t = {t_lock:.3f} s; servo: {servo.describe()}; K_p = {feedback} 1/s")
    print(
        f"jump at the lock {s.get('jump_at_lock', 0.0):.4g} (rad/s)²; path error peak after the lock "
        f"{1e3 * s['path_error_peak_after_lock']:.3f} mm (before: {1e3 * s['path_error_max_before_lock']:.3f} mm)"
    )
    if args.out:
        out = Path(args.out)
        run.save(out)
        from . import plots

        plots.save_figure(plots.plot_lock({f"{joint} locks at {t_lock:.2f} s": run}), out / "lock")
        plots.save_figure(plots.plot_run(run), out / "run")
        if args.html:
            from .viz import export_html

            export_html(run, out / "replay.html", arm=arm)
        print(f"wrote {out}/ (run.npz, run.csv, summary.json, lock.png/.svg)")
    return 0


def cmd_reproduce(args) -> int:
    """Every case of the paper into --out."""
    from .experiments import reproduce

    cases = _names(args.cases)
    out = Path(args.out)
    try:
        summary = reproduce(
            out, cases=cases, quick=args.quick, progress=not args.no_progress, html=args.html
        )
    except KeyboardInterrupt:
        print(
            f"interrupted: finished cases are in {out}; see {out / 'summary.partial.json'} for what "
            "was not finished (an earlier summary.json is left as it was)",
            file=sys.stderr,
        )
        return 130
    print(
        f"wrote {out}/summary.json, {out}/REPORT.md and figures in {summary['meta']['seconds']} s"
    )
    return 0


def cmd_replay(args) -> int:
    """Meshcat replay of a saved run."""
    from .viz import replay_main

    return replay_main(args.run, open=args.open, html=args.html, speed=args.speed)


def cmd_bench(args) -> int:
    """The performance benchmark."""
    from . import bench

    return bench.run(args)


# -- parser ---------------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error message (exit code 2)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``fault-tolerance``."""
    fmt = argparse.RawDescriptionHelpFormatter
    p = _Parser(
        prog="fault-tolerance",
        formatter_class=fmt,
        description="Minimum joint-velocity-jump redundancy resolution for locked-joint failures "
        "(Zhao & Li), on Pinocchio.",
        epilog=textwrap.dedent("""\
            examples:
              fault-tolerance reproduce --out reproduce_out
              fault-tolerance simulate --robot planar_3r --out out/fig2
              fault-tolerance replay out/fig2/jvja --html replay.html"""),
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser(
        "robots",
        help="list shipped and example-robot-data arms",
        epilog=_epilog("robots"),
        formatter_class=fmt,
    )
    s.set_defaults(func=cmd_robots)

    s = sub.add_parser(
        "inspect",
        help="kinematic tree, chosen chain and task, intolerable joints",
        epilog=_epilog("inspect"),
        formatter_class=fmt,
    )
    s.add_argument("target", help="shipped / example-robot-data name or URDF path")
    s.add_argument("--tip", default=None)
    s.add_argument("--task", default=None)
    s.add_argument("--joints", default=None)
    s.add_argument("--package-dir", action="append", default=[])
    s.set_defaults(func=cmd_inspect)

    s = sub.add_parser(
        "simulate",
        help="one task run with one or several algorithms",
        epilog=_epilog("simulate"),
        formatter_class=fmt,
    )
    add_robot_options(s)
    add_path_options(s)
    s.add_argument(
        "--algorithms", default="lnva,jvja,mda", help="comma-separated among lnva,jvja,mda"
    )
    s.add_argument("--out", default=None, help="output folder")
    s.add_argument(
        "--html", action="store_true", help="also write a self-contained replay.html per run"
    )
    s.add_argument("--no-progress", action="store_true")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser(
        "lock",
        help="a run in which a joint locks (servo model on)",
        epilog=_epilog("lock"),
        formatter_class=fmt,
    )
    add_robot_options(s)
    add_path_options(s)
    s.add_argument("--joint", required=True, help="the joint that locks")
    s.add_argument(
        "--at",
        default="max",
        help="lock time [s], or max / min: the moment of largest / smallest jump",
    )
    s.add_argument("--algorithm", default="lnva", choices=["lnva", "jvja", "mda"])
    s.add_argument("--tau", type=float, default=0.05, help="servo time constant [s] (default 0.05)")
    s.add_argument(
        "--accel-limit", type=float, default=float("inf"), help="servo acceleration limit [rad/s²]"
    )
    s.add_argument("--out", default=None)
    s.add_argument("--html", action="store_true", help="also write a self-contained replay.html")
    s.add_argument("--no-progress", action="store_true")
    s.set_defaults(func=cmd_lock)

    s = sub.add_parser(
        "reproduce",
        help="every case of the paper: figures, summary.json, REPORT.md",
        epilog=_epilog("reproduce"),
        formatter_class=fmt,
    )
    s.add_argument("--out", default="reproduce_out", help="output folder (default reproduce_out)")
    s.add_argument("--cases", default=None, help="subset, e.g. fig2,fig4,experiment")
    s.add_argument("--quick", action="store_true", help="shortened runs (for tests)")
    s.add_argument("--html", action="store_true", help="also write meshcat replays (replay.html)")
    s.add_argument("--no-progress", action="store_true")
    s.set_defaults(func=cmd_reproduce)

    s = sub.add_parser(
        "replay",
        help="meshcat replay of a saved run",
        epilog=_epilog("replay"),
        formatter_class=fmt,
    )
    s.add_argument("run", help="folder of a saved run (with run.npz)")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--open", action="store_true", help="serve it on 127.0.0.1 and print the URL")
    g.add_argument("--html", default=None, help="write one self-contained HTML file")
    s.add_argument("--speed", type=float, default=1.0, help="playback speed factor (default 1)")
    s.set_defaults(func=cmd_replay)

    from .sweep_cli import add_parsers

    add_parsers(sub, fmt, add_robot_options)

    s = sub.add_parser(
        "bench", help="the performance benchmark", epilog=_epilog("bench"), formatter_class=fmt
    )
    try:
        from . import bench

        bench.add_arguments(s)
    except ImportError:  # pragma: no cover - bench lands separately
        pass
    s.set_defaults(func=cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    shown = warnings.showwarning
    if not args.debug:  # a warning is one line on stderr too
        warnings.showwarning = _warning_line
    try:
        return int(args.func(args) or 0)
    except FaultToleranceError as err:
        if args.debug:
            raise
        print(f"fault-tolerance {args.command}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # noqa: BLE001 - the last line of defence
        if args.debug:
            raise
        print(
            f"fault-tolerance {args.command}: unexpected error: {type(err).__name__}: "
            f"{_one_line(err)} (run with --debug for the traceback)",
            file=sys.stderr,
        )
        return 1
    finally:
        warnings.showwarning = shown


def _one_line(message) -> str:
    return " ".join(str(message).split("\n"))


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"fault-tolerance: warning: {_one_line(message)}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
