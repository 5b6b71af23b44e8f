"""``fault-tolerance lock``: a run in which a joint locks (servo model on)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fault_tolerance.cli.common import (
    FORMATTER,
    add_path_options,
    add_robot_options,
    bar,
    epilog,
    floats,
    limits_line,
    load_robot,
    names,
    resolver_options,
)
from fault_tolerance.cli.dynamics_options import (
    add_dynamics_options,
    check_dynamics_args,
    dynamics_model,
    print_torque_table,
)
from fault_tolerance.cli.simulate import announce_first_run, first_run_engine
from fault_tolerance.cli.start_options import choose_start, print_start
from fault_tolerance.errors import InvalidInput

NAME = "lock"
HELP = "a run in which a joint locks (servo model on)"
EXAMPLE = (
    "fault-tolerance lock --robot powercube_3r --joint joint3 --at max --out out/lock_max\n"
    "  fault-tolerance lock --robot planar_3r --joint joint2 --at 0.4 --tau 0.02 --out out/lock\n"
    "  fault-tolerance lock --robot panda --joint panda_joint4 --at 0.5 --dynamics --duration 1"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``lock`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    add_robot_options(s)
    add_path_options(s)
    s.add_argument("--joint", required=True, help="the joint that locks")
    s.add_argument(
        "--at",
        default="max",
        help="lock time [s], or max / min: the moment of largest / smallest jump of the planned "
        "run (default: max)",
    )
    from fault_tolerance.simulation.simulate import algorithms

    s.add_argument(
        "--algorithm",
        default="lnva",
        choices=list(algorithms()),  # the registered resolvers, then the path planners
        help="the planner before the lock (default: lnva, as in the paper's Sec. V); with "
        "--dynamics: the one whose planned run places --at max/min",
    )
    s.add_argument(
        "--algorithms",
        default=None,
        help="with --dynamics: the planners compared, comma-separated (default: every one, "
        f"{','.join(algorithms())}), each locked at the same time from the same start",
    )
    add_dynamics_options(s, lock=True)
    s.add_argument("--tau", type=float, default=0.05, help="servo time constant [s] (default 0.05)")
    s.add_argument(
        "--accel-limit",
        type=float,
        default=float("inf"),
        help="servo acceleration limit [rad/s²] (default: inf, no limit)",
    )
    s.add_argument("--out", default=None, help="output folder (default: none, nothing written)")
    s.add_argument("--html", action="store_true", help="also write a self-contained replay.html")
    s.add_argument(
        "--no-progress", action="store_true", help="no progress bar (default: the bar is shown)"
    )
    s.set_defaults(func=run)
    return s


#: λ [(rad/s)²] at or below which a planned run's jump counts as zero (eq. 8 holds to rounding).
ZERO_JUMP = 1e-24


def _lock_time(args, arm, path, q0, joint: str, duration: float, gain: dict, lockable, feedback):
    """``--at``: a time, or the moment of the largest / smallest jump of the planned run.

    The planned run is the lock run without its lock: the same lockable joints and feedback gain,
    so the moment is chosen on the motion the lock then interrupts; λ is its total (9)/(10), and
    the locking joint's own part is printed beside it.

    Returns ``(t_lock, planned)``; ``planned`` is the run without a lock (``None`` for a time).
    """
    from fault_tolerance.figures.runs import planned_jump
    from fault_tolerance.simulation.simulate import simulate

    if args.at not in ("max", "min"):
        return float(floats(args.at, "--at")[0]), None
    planned = simulate(
        arm,
        path,
        args.algorithm,
        q0=q0,
        lockable=lockable,
        dt=args.dt,
        duration=duration,
        feedback_gain=feedback,
        response=args.response,
        limits=not args.no_limits,
        **gain,
    )
    top = float(np.max(planned.jvj))
    if top <= ZERO_JUMP:  # λ ≡ 0 to rounding: no moment has a larger jump than another
        t_lock = float(planned.t[0])
        print(
            f"the planned run's jump of {joint} is zero at every sample to rounding (largest "
            f"λ = {top:.3g} (rad/s)² <= {ZERO_JUMP:g}): no moment of {args.at} jump exists; "
            f"the lock is at the first sample, t = {t_lock:.3f} s"
        )
        return t_lock, planned
    k = int(np.argmax(planned.jvj) if args.at == "max" else np.argmin(planned.jvj))
    t_lock = float(planned.t[k])
    print(  # the λ the figure's last panel marks (plots.planned_jump)
        f"{args.at} jump of {joint} in the planned run at t = {t_lock:.3f} s "
        f"(λ = {planned_jump(planned, t_lock):.4g} (rad/s)²{_own_part(planned, joint, k)})"
    )
    return t_lock, planned


def _own_part(planned, joint: str, k: int) -> str:
    """``", of which joint2 0.12"``: the locking joint's scenario's part of λ at sample ``k``."""
    sets = planned.meta.get("lockable") or []
    if [joint] not in sets or len(sets) == 1:
        return ""
    return f", of which {joint}'s lock {planned.jvj_parts[k, sets.index([joint])]:.4g}"


def run(args) -> int:
    """A run in which a joint locks; ``--out`` is locked while written and appears whole."""
    from fault_tolerance.simulation.run import RUN_FILES
    from fault_tolerance.storage.folder_io import check_path_names
    from fault_tolerance.storage.folder_lock import FolderLock
    from fault_tolerance.storage.result_folder import check_target

    check_dynamics_args(args)
    if args.dynamics:
        return _run_dynamics(args)
    if not args.out:
        return _run(args)
    out = check_path_names(Path(args.out))
    with FolderLock(out):
        check_target(out, RUN_FILES)  # refuse a bad --out before the runs
        return _run(args)


def _run(args) -> int:
    from fault_tolerance.simulation.setup import ServoModel
    from fault_tolerance.simulation.simulate import simulate

    arm = load_robot(args)
    joint = arm.joint_names[arm.joint_index(args.joint)]
    servo = ServoModel(tau=args.tau, accel_limit=args.accel_limit)
    feedback = 10.0 if args.feedback is None else args.feedback
    gain = {} if args.gain is None else {"gain": args.gain}
    resolver = resolver_options(args, [args.algorithm])  # --option, checked before any work
    if resolver:
        gain["options"] = resolver
    gain["engine"] = first_run_engine(args, 3)  # with the gain, into every run (cli/simulate.py)
    # the start is checked with the planned (lock-free) run; the locking joint must be tolerable
    q0, path, lockable, choice = choose_start(
        args,
        arm,
        [args.algorithm],
        extra_lockable=[joint],
        duration=args.duration,
        response=args.response,
        limits=not args.no_limits,  # the start's checks run the same formulation as the lock run
        **gain,
    )
    duration = args.duration or path.duration
    if args.at not in ("max", "min"):
        t_at = float(floats(args.at, "--at")[0])
        if not 0 <= t_at <= duration:
            raise InvalidInput(f"lock time must be within [0, {duration}] s, got {t_at}")
    print_start(args, arm, q0, choice)
    announce_first_run(gain["engine"])
    t_lock, planned = _lock_time(args, arm, path, q0, joint, duration, gain, lockable, feedback)
    progress = bar(int(round(duration / args.dt)) + 1, not args.no_progress, "lock")
    run_ = simulate(
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
        progress=progress,
        limits=not args.no_limits,
        **gain,
    )
    if progress:
        progress.close()
    s = run_.summary()
    print(f"{joint} locks at t = {t_lock:.3f} s; servo: {servo.describe()}; K_p = {feedback} 1/s")
    print(
        f"jump at the lock instant t = {t_lock:.3f} s: ‖q̇_after − q̇_before‖² = "
        f"{s.get('jump_at_lock', 0.0):.4g} (rad/s)²; path error peak after the lock "
        f"{1e3 * s['path_error_peak_after_lock']:.3f} mm (before: {1e3 * s['path_error_max_before_lock']:.3f} mm)"
    )
    if run_.orientation_error is not None:  # radians apart from metres
        after = run_.t >= t_lock
        print(
            f"orientation error peak after the lock {1e3 * run_.orientation_error[after].max():.3f} "
            f"mrad (whole run: {1e3 * s['orientation_error_max']:.3f} mrad)"
        )
    setup = (q0, path, lockable, duration, feedback, gain, joint, t_lock)
    found = _report(args, arm, run_, setup)
    print(limits_line(run_))
    if args.out:
        _write(run_, arm, joint, t_lock, Path(args.out), args.html, found, planned)
    return 0


def _lag_free(args, arm, run_, setup):
    """The lock run with perfect rate tracking (``tau = 0``): the same start, lock and samples."""
    from fault_tolerance.simulation.setup import ServoModel
    from fault_tolerance.simulation.simulate import simulate

    q0, path, lockable, duration, feedback, gain, joint, t_lock = setup
    return simulate(
        arm, path, args.algorithm, q0=q0, lockable=lockable, dt=args.dt, duration=duration,
        lock_joint=joint, lock_time=t_lock, servo=ServoModel(tau=0.0), feedback_gain=feedback,
        response=args.response, limits=not args.no_limits, **gain,
    )  # fmt: skip


def _report(args, arm, run_, setup) -> list[dict]:
    """The run's warnings on stderr, the servo's lag kept out of them and noted on stdout.

    The tracking and lost-path checks judge the same run with perfect rate tracking (the
    algorithm's and the reduced robot's error); the lag's part is one note
    (:mod:`~fault_tolerance.simulation.diagnostics`, (E1), (E2)).
    """
    import sys

    from fault_tolerance.simulation.diagnostics import check_run, servo_lag, warning_lines

    lag_free = _lag_free(args, arm, run_, setup)
    found = check_run(run_, arm, lag_free=lag_free)
    for line in warning_lines(args.algorithm, found):
        print(f"fault-tolerance {NAME}: {line}", file=sys.stderr)
    note = servo_lag(run_, lag_free)
    if note:
        print(f"note: {note}")
    return [w.as_dict() for w in found]


def _write(run_, arm, joint: str, t_lock: float, out: Path, html: bool, found, planned) -> None:
    from fault_tolerance.figures import runs as plots

    def extras(folder: Path) -> None:  # written with the run, in its staging folder
        title = f"{joint} locks at {t_lock:.2f} s"
        plots.save_figure(plots.plot_lock({title: run_}, planned=planned), folder / "lock")
        plots.save_figure(plots.plot_run(run_), folder / "run")
        if html:
            from fault_tolerance.viz.page import export_html

            export_html(run_, folder / "replay.html", arm=arm)

    run_.save(out, extras=extras, warnings=found)
    print(f"wrote {out}/ (run.npz, run.csv, summary.json, lock.png/.svg)")


def _dynamics_algorithms(args) -> list[str]:
    """``--algorithms`` of ``lock --dynamics``: every registered resolver and planner by default."""
    from fault_tolerance.simulation.simulate import algorithms

    if args.algorithms is None:
        return list(algorithms())
    algs = names(args.algorithms) or []
    bad = [a for a in algs if a not in algorithms()]
    if bad or not algs:
        raise InvalidInput(f"--algorithms {args.algorithms!r}: choose among {list(algorithms())}")
    return algs


def _run_dynamics(args) -> int:
    """``lock --dynamics``: every planner, the ideal and the finite brake, the same start and time."""
    from fault_tolerance.resolution.registry import names as registered
    from fault_tolerance.simulation.setup import TRACKED_PAST_PLAN
    from fault_tolerance.simulation.simulate import options_for, simulate
    from fault_tolerance.storage.atomic import output_folder

    arm = load_robot(args)
    joint = arm.joint_names[arm.joint_index(args.joint)]
    algs = _dynamics_algorithms(args)
    feedback = 10.0 if args.feedback is None else args.feedback
    gain = {} if args.gain is None else {"gain": args.gain}
    resolver = resolver_options(args, algs)  # --option, checked before any work
    common = dict(duration=args.duration, response=args.response, limits=not args.no_limits)
    stepwise = [a for a in algs if a in registered()] or [TRACKED_PAST_PLAN]  # checks the start
    q0, path, lockable, choice = choose_start(
        args, arm, stepwise, extra_lockable=[joint], **common, **gain
    )
    print_start(args, arm, q0, choice)
    duration = args.duration or path.duration
    t_lock, _ = _lock_time(args, arm, path, q0, joint, duration, gain, lockable, feedback)
    brake = _brake_torque(args, arm, joint)
    models = {"ideal": dynamics_model(args), f"finite {brake:g} N·m": dynamics_model(args, brake)}
    out = output_folder(Path(args.out)) if args.out else None
    rows = {}
    for alg in algs:
        for label, model in models.items():
            run_ = simulate(
                arm, path, alg, q0=q0, lockable=lockable, dt=args.dt, duration=duration,
                lock_joint=joint, lock_time=t_lock, feedback_gain=feedback,
                response=args.response, limits=not args.no_limits, dynamics=model, **gain,
                options=options_for(alg, resolver),
            )  # fmt: skip
            rows[(alg, label)] = run_.summary()
            if out:
                run_.save(out / f"{alg}_{label.split()[0]}")
    print(
        f"{joint} locks at t = {t_lock:.3f} s; {models['ideal'].describe()}; K_p = {feedback} 1/s"
    )
    print_torque_table(rows)
    if out:
        print(f"wrote {out}/ (one run folder per algorithm and brake: ALG_ideal, ALG_finite)")
    return 0


def _brake_torque(args, arm, joint: str) -> float:
    """``--brake-torque``, or the locked joint's effort limit."""
    if args.brake_torque is not None:
        return float(args.brake_torque)
    effort = float(arm.model.effortLimit[arm.joint_index(joint)])
    if not (np.isfinite(effort) and effort > 0):
        raise InvalidInput(
            f"{joint} has no effort limit in the description; give the finite brake's torque "
            "with --brake-torque N·m"
        )
    return effort
