"""Where a command's run starts: ``--q0``, ``--x0``, ``--csv``, or the default start.

:func:`choose_start` is shared by ``simulate`` and ``lock``. A given start (``--q0``, ``--x0`` or
the first point of a ``--csv`` path) is used as given or through the posture search, and a
lockable joint intolerable there is refused with an error that says whether it is structural or
proposes a start that works. Without one, :func:`~fault_tolerance.planning.default_start.default_start` chooses the
start (docs/MATH.md, "The default start") and one line says which and why.
"""

from __future__ import annotations

import copy
import itertools

import numpy as np

from fault_tolerance.cli.common import (
    joint_values,
    lockable_of,
    names,
    start_line,
    task_values,
)
from fault_tolerance.errors import InvalidInput, NoStartFound, StructurallyIntolerable


def _none_ok(algorithms) -> bool:
    """``--lockable none`` suits runs whose rates do not depend on the lockable set."""
    return all(a == "lnva" for a in algorithms)


def choose_start(
    args, arm, algorithms=("jvja",), extra_lockable=(), *, fixes=True, max_seeds=None, **sim_options
):
    """``(q0, path, lockable, choice)`` from the options.

    ``algorithms`` and ``sim_options`` (``dt``, ``feedback_gain``, ...) are those of the runs that
    follow: the default start is checked by running them, and ``choice.runs`` holds those runs
    (``choice`` is ``None`` for a given start). The command prints ``choice.reason()`` (one line)
    once its inputs are all checked, so bad input still gives nothing on stdout. ``extra_lockable``: joints that must be tolerable
    at the start as well (``lock --joint``). When no default start passes, the refusal
    (:class:`~fault_tolerance.errors.NoStartFound`) says why by category and, with ``fixes``,
    proposes the option changes whose own start search passed (:func:`refusal_with_fixes`);
    ``max_seeds`` bounds the seeds of that search (default: the full budget).
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
            _check_found(args, arm, q0)
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
    if max_seeds is not None:
        options["max_seeds"] = max_seeds
    try:
        choice = default_start(arm, start_lockable, x0=x0, path=circle, **options)
    except (NoStartFound, StructurallyIntolerable) as err:
        if not fixes:
            raise
        raise refusal_with_fixes(
            args, arm, err, start_lockable, (algorithms, extra_lockable, sim_options)
        ) from None
    return choice.q0, circle(choice.x0), lockable, choice


def _check_found(args, arm, q0) -> None:
    """The minimum-RCN start at ``--x0`` (or at the first point of ``--csv``) inside the limits."""
    from fault_tolerance.model.joint_limits import check_found_start

    if not getattr(args, "no_limits", False):
        check_found_start(arm, q0, "the first point of --csv" if args.csv else "--x0")


def refusal_with_fixes(args, arm, err, lockable, rerun) -> NoStartFound:
    """``err`` (no default start) with the fixes whose own start search found a start.

    The candidate fixes follow the dominant failure reasons (:func:`fix_options`); each is tried
    by re-running :func:`choose_start` with that option changed and a smaller seed budget
    (:data:`~fault_tolerance.planning.default_start.FIX_SEEDS`), at most two that work, within
    :data:`~fault_tolerance.planning.default_start.FIX_TIME_CAP` seconds.
    ``rerun``: ``(algorithms, extra_lockable, sim_options)`` of the refused search.
    """
    from fault_tolerance.cli.common import load_robot
    from fault_tolerance.planning.default_start import (
        CHECK_HORIZON,
        FIX_SEEDS,
        fixes_line,
        try_fixes,
    )
    from fault_tolerance.planning.start_checks import STRUCTURAL

    algorithms, extra, sim_options = rerun
    if isinstance(err, StructurallyIntolerable):
        reasons = [(STRUCTURAL, 1, tuple(err.joints))]
    else:
        reasons = err.reasons
    still = tuple(getattr(err, "still", ()))

    def attempt(changes: dict):
        def run():
            fixed = copy.copy(args)
            for k, v in changes.items():
                setattr(fixed, k, v)
            again = load_robot(fixed) if {"task", "tip"} & set(changes) else arm
            choose_start(fixed, again, algorithms, extra, fixes=False, max_seeds=FIX_SEEDS,
                         **sim_options)  # fmt: skip

        return run

    options = fix_options(args, arm, reasons, lockable, extra, still)
    trials = try_fixes((text, attempt(changes)) for text, changes in options)
    capped = CHECK_HORIZON if _path_spec(args, arm)[2] > CHECK_HORIZON else None
    return NoStartFound(
        f"{err}; {fixes_line(trials, capped)}{_no_tip_past(arm, still, options)}",
        reasons,
        [t.option for t in trials if t.works],
        still=still,
    )


def _no_tip_past(arm, still, options) -> str:
    """What to do when the tip lies at the wrist centre and no frame past it can be proposed."""
    if not still or any(text.startswith("--tip ") for text, _ in options):
        return ""
    link = arm.model.names[arm.model.frames[arm.frame_id].parentJoint]
    return (
        f"; no --tip to propose: no other frame is attached to the tip's link (after {link}) "
        f"away from the wrist centre; a tool frame in the description (a fixed joint from "
        f"{arm.tip} to a link past the wrist) gives one"
    )


def fix_options(args, arm, reasons, lockable, extra=(), still=()) -> list[tuple[str, dict]]:
    """Candidate fixes ``(option text, changed args)`` for the failure ``reasons``, best first.

    Lockable joints that fail (structurally, under limits, nearly intolerable) are left out of
    ``--lockable``; a path too fast gets a slower ``--omega``, a smaller ``--radius`` or another
    plane (``--rows``: other joints may move the tool there); a path
    out of reach a smaller ``--radius`` or another plane (``--rows``); a singular arm the task
    rows its Jacobian spans (``--task``) or another plane. A structurally intolerable joint may
    also be made up for from another tip frame on the last link (``--tip``, farthest first).
    ``still``: joints that do not move the tip (the tip at the wrist centre); then the tip frames
    past the wrist on the last link (``--tip``) come first.
    """
    from fault_tolerance.planning import start_checks as sc

    out: list[tuple[str, dict]] = _past_the_wrist(arm, lockable, extra) if still else []
    radius, omega, _ = _path_spec(args, arm)
    for category, _, joints in reasons:
        if category == sc.STRUCTURAL:
            every = _every_structural(arm, lockable, joints)
            out += _without(lockable, every, extra) if every != tuple(joints) else []
            out += _without(lockable, joints, extra) + _spanned_task(args, arm)
            out += _other_tips(arm)
        elif category in (sc.UNDER_LIMITS, sc.NEARLY_INTOLERABLE):
            out += _without(lockable, joints, extra)
            out += [_set("omega", omega / 2), _set("radius", radius / 2)]
            out += [_set("omega", omega / 5), _set("radius", radius / 5)]
        elif category == sc.TOO_FAST:  # another plane may need only the faster joints
            out += [_set("omega", omega / 2), _set("radius", radius / 2)]
            out += [*_other_planes(args, arm)[:2], _set("omega", omega / 5)]
            out += [_set("radius", radius / 5)]
        elif category == sc.OUT_OF_REACH:
            out += [
                _set("radius", radius / 2),
                *_other_planes(args, arm),
                _set("radius", radius / 5),
            ]
        elif category in (sc.SINGULAR, sc.NEAR_LIMIT):
            out += _spanned_task(args, arm) + _other_planes(args, arm)
    return list({text: (text, changes) for text, changes in out}.values())


def _past_the_wrist(arm, lockable, extra) -> list[tuple[str, dict]]:
    """Fixes of a tip at the wrist centre: a tip frame past it, the joints others make up there."""
    from fault_tolerance.planning.start_checks import often_tolerable

    spare = set(often_tolerable(arm, lockable))
    drop = tuple(n for n in lockable if isinstance(n, str) and n not in spare)
    return _other_tips(arm) + (_without(lockable, drop, extra)[:1] if spare and drop else [])


def _every_structural(arm, lockable, joints) -> tuple[str, ...]:
    """``joints`` and every other lockable joint that no start can make up.

    One fix drops them all: the start search stops at the first such joint, so a fix that drops
    only that one meets the next.
    """
    from fault_tolerance.planning.start_checks import intolerable_everywhere

    singles = [(j,) for j in lockable if isinstance(j, str) and j not in joints]
    found = [s[0] for s in intolerable_everywhere(arm, singles)] if singles else []
    return (*joints, *found)


def _set(option: str, value: float) -> tuple[str, dict]:
    """``("--option VALUE", {option: VALUE})`` with VALUE to 4 significant digits."""
    value = float(f"{value:.4g}")
    return f"--{option} {value:g}", {option: value}


def _path_spec(args, arm) -> tuple[float, float, float]:
    """The circle's radius [m], angular rate [rad/s] and duration [s] the refused search used."""
    from fault_tolerance.model.catalog import catalog

    entry = catalog().get(arm.name) if arm.source == arm.name else None
    spec = (entry or {}).get("path", {})
    radius = args.radius if args.radius is not None else spec.get("radius", 0.05)
    omega = args.omega if args.omega is not None else spec.get("omega", 2 * np.pi)
    return float(radius), float(omega), float(args.duration or spec.get("duration", 1.0))


def _without(lockable, joints, extra) -> list[tuple[str, dict]]:
    """``--lockable`` without the scenarios that name ``joints``, then without each one alone.

    A ``lock --joint`` among ``joints`` cannot be left out; an empty ``--lockable`` is no fix.
    """
    extra = {e if isinstance(e, str) else e[0] for e in extra}
    out = []
    for drop in [set(joints), *({j} for j in joints[:2])] if len(joints) > 1 else [set(joints)]:
        if drop & extra:
            continue
        keep = [i for i in lockable if not drop & set((i,) if isinstance(i, str) else i)]
        keep = [i for i in keep if i not in extra]
        if keep:
            text = ",".join(i if isinstance(i, str) else "+".join(i) for i in keep)
            out.append((f"--lockable {text}", {"lockable": text}))
    return out


def _other_planes(args, arm) -> list[tuple[str, dict]]:
    """``--rows`` with the other pairs of task rows (translations first)."""
    rows = list(arm.task)
    now = tuple(names(args.rows) or rows[:2]) if args.rows else None
    pairs = [
        p for p in itertools.combinations(rows, 2) if p != now and (now or p != tuple(rows[:2]))
    ]
    pairs.sort(key=lambda p: sum(r.startswith("r") for r in p))
    return [(f"--rows {a},{b}", {"rows": f"{a},{b}"}) for a, b in pairs[:3]]


def _other_tips(arm, count: int = 2) -> list[tuple[str, dict]]:
    """``--tip`` with other body or fixed frames on the tip's link, farthest from its joint first."""
    import pinocchio as pin

    model = arm.model
    joint = model.frames[arm.frame_id].parentJoint
    kinds = (pin.FrameType.BODY, pin.FrameType.OP_FRAME)
    found: dict[str, float] = {}
    for f in model.frames:
        if f.parentJoint == joint and f.type in kinds and f.name != arm.tip:
            found.setdefault(f.name, float(np.linalg.norm(f.placement.translation)))
    here = float(np.linalg.norm(model.frames[arm.frame_id].placement.translation))
    far = sorted((d, n) for n, d in found.items() if abs(d - here) > 1e-6)[::-1]
    return [(f"--tip {n}", {"tip": n}) for _, n in far[:count]]


def _spanned_task(args, arm, samples: int = 20, seed: int = 0) -> list[tuple[str, dict]]:
    """``--task`` with the rows the Jacobian moves (rows zero at every sample left out)."""
    from fault_tolerance.planning.start_checks import still_rows

    still = still_rows(arm, 1e-9, samples, seed)
    kept = [r for r in arm.task if r not in still]
    out = []
    if 2 <= len(kept) < len(arm.task) and len(kept) < arm.n:
        out.append((f"--task {','.join(kept)}", {"task": ",".join(kept), "rows": None}))
    if len(arm.task) == 6 and arm.n > 3:
        out.append(("--task position", {"task": "position", "rows": None}))
    return out


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
