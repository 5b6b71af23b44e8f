"""Where a command's run starts: ``--q0``, ``--x0``, ``--csv``, or the default start.

:func:`choose_start` is shared by ``simulate`` and ``lock``. A given start (``--q0``, ``--x0`` or
the first point of a ``--csv`` path) is used as given or through the posture search, and a
lockable joint intolerable there is refused with an error that says whether it is structural or
proposes a start that works. Without one, :func:`~fault_tolerance.planning.default_start.default_start` chooses the
start (docs/MATH.md, "The default start") and one line says which and why.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.cli.common import (
    joint_values,
    lockable_of,
    names,
    start_line,
    task_values,
)
from fault_tolerance.errors import InvalidInput


def _none_ok(algorithms) -> bool:
    """``--lockable none`` suits runs whose rates do not depend on the lockable set."""
    return all(a == "lnva" for a in algorithms)


def choose_start(args, arm, algorithms=("jvja",), extra_lockable=(), **sim_options):
    """``(q0, path, lockable, choice)`` from the options.

    ``algorithms`` and ``sim_options`` (``dt``, ``feedback_gain``, ...) are those of the runs that
    follow: the default start is checked by running them, and ``choice.runs`` holds those runs
    (``choice`` is ``None`` for a given start). The command prints ``choice.reason()`` (one line)
    once its inputs are all checked, so bad input still gives nothing on stdout. ``extra_lockable``: joints that must be tolerable
    at the start as well (``lock --joint``).
    """
    from fault_tolerance.model.catalog import catalog
    from fault_tolerance.planning.default_start import check_start, default_start
    from fault_tolerance.planning.posture import initial_posture, lockable_scenarios
    from fault_tolerance.simulation.paths import load_csv
    from fault_tolerance.storage.budget import run_samples

    entry = catalog().get(arm.name) if arm.source == arm.name else None
    if not (np.isfinite(args.dt) and args.dt > 0):
        raise InvalidInput(f"--dt must be a finite number > 0 [s], got {args.dt}")
    if args.duration is not None and not (np.isfinite(args.duration) and args.duration > 0):
        raise InvalidInput(f"--duration must be a finite number > 0 [s], got {args.duration}")
    lockable = lockable_of(args, arm, none_ok=bool(extra_lockable) and _none_ok(algorithms))
    lockable = lockable or list(extra_lockable)  # none: only the extra joints are measured
    start_lockable = _with_joints(arm, lockable, extra_lockable)
    q0 = None if args.q0 is None else given_start(args, arm)
    circle = _circle_maker(args, arm, entry)
    options = {"algorithms": tuple(algorithms), "dt": args.dt, **sim_options}
    if args.csv or args.x0 is not None or q0 is not None:
        if args.csv:
            path = load_csv(args.csv, rows=list(arm.task) if len(arm.task) else None)
        else:
            x0 = (
                task_values(args.x0, "--x0", arm, getattr(args, "deg", False))
                if args.x0 is not None
                else arm.fk(q0)
            )
            path = circle(x0)
        if q0 is None:
            q0 = initial_posture(arm, path.x0, start_lockable).q
        elif np.linalg.norm(arm.task_error(path.x0, q0)) > 1e-6:
            raise InvalidInput(
                f"--q0 puts the tool at {arm.fk(q0).round(4).tolist()}, not at the path's start "
                f"{np.round(path.x0, 4).tolist()}"
            )
        run_samples(args.dt, args.duration or path.duration)  # a run too long: refused first
        sc = lockable_scenarios(arm, start_lockable)
        check_start(arm, sc, q0, x0=path.x0, path=path, fallback_path=circle, **options)
        return q0, path, lockable, None
    x0 = np.array(entry["x0"], dtype=float) if entry and "x0" in entry else None
    if arm.m >= 2:  # a run too long is refused before the search
        run_samples(args.dt, args.duration or circle(np.zeros(arm.m)).duration)
    choice = default_start(arm, start_lockable, x0=x0, path=circle, **options)
    return choice.q0, circle(choice.x0), lockable, choice


def given_start(args, arm) -> np.ndarray:
    """``--q0`` [rad; ``--deg``: degrees on angular joints] checked as a start (docs/units.md).

    Refused (exit 2) outside the joint limits (with limits on), and beyond a turn on a revolute
    joint (also with ``--no-limits``), with a hint when the value looks like degrees.
    """
    from fault_tolerance.model.joint_limits import check_start, wrap_into_limits

    q0 = joint_values(args.q0, "--q0", arm, getattr(args, "deg", False))
    limits = not getattr(args, "no_limits", False)
    q0 = check_start(arm, q0, limits=limits)
    return wrap_into_limits(arm, q0) if limits else q0  # where the run starts (simulate wraps)


def start_origin(args, choice) -> str:
    """Where the start came from, for :func:`print_start`."""
    if args.q0 is not None:
        return "given by --q0" + (", in degrees" if getattr(args, "deg", False) else "")
    if choice is not None:
        return "the default start, chosen: see the next line"
    where = "the first point of --csv" if args.csv else "--x0"
    return f"the minimum-RCN posture at {where}"


def print_start(args, arm, q0, choice) -> None:
    """The start line (every command that takes or picks a start), then the choice's reason."""
    origin = start_origin(args, choice)
    if args.q0 is not None:  # full-turn joints read modulo 2π into their limits: say which
        given = joint_values(args.q0, "--q0", arm, getattr(args, "deg", False))
        moved = [arm.joint_names[i] for i in np.flatnonzero(np.abs(given - q0) > 1e-12)]
        origin += f"; {', '.join(moved)} read modulo 2π into the limits" if moved else ""
    print(start_line(arm, q0, origin, getattr(args, "deg", False)))
    if choice is not None:
        print(choice.reason())


def start_and_path(args, arm):
    """``(q0, path, lockable)`` from the options (see :func:`choose_start`)."""
    q0, path, lockable, _ = choose_start(args, arm)
    return q0, path, lockable


def _with_joints(arm, lockable, joints) -> list:
    """``lockable`` (``None``: the arm's default) with the single-joint scenarios ``joints`` added."""
    items = list(arm.default_lockable if lockable is None else lockable)
    for j in joints:
        if j not in items and (j,) not in items:
            items.append(j)
    return items


def _circle_maker(args, arm, entry):
    """A callable ``x0 -> CirclePath`` from ``--radius/--omega/--rows/--duration`` and the catalog."""
    from fault_tolerance.simulation.paths import CirclePath

    spec = (entry or {}).get("path", {})
    if args.rows:
        chosen = names(args.rows) or []
        if len(chosen) != 2 or any(r not in arm.task for r in chosen) or chosen[0] == chosen[1]:
            raise InvalidInput(
                f"--rows must name two different task rows among {list(arm.task)}, "
                f"got '{args.rows}'"
            )
        rows = (arm.task.index(chosen[0]), arm.task.index(chosen[1]))
    else:
        rows = tuple(spec.get("rows", (0, 1)))
    if arm.m < 2 and not args.csv:
        raise InvalidInput("a circle needs at least two task rows; give a path with --csv")
    radius = args.radius if args.radius is not None else spec.get("radius", 0.05)
    omega = args.omega if args.omega is not None else spec.get("omega", 2 * np.pi)
    duration = args.duration or spec.get("duration", 1.0)
    sign = spec.get("sign", 1.0)

    def circle(x0):
        if arm.m < 2:
            return None
        return CirclePath(
            np.asarray(x0, dtype=float), radius, omega, duration, rows=rows, sign=sign
        )

    return circle
