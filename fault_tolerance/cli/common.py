"""What the commands share: robot, start and path options, parsing helpers, exit codes.

The parser and the mapping of errors to exit codes are in :mod:`.runner`.

Exit codes of ``fault-tolerance``: :data:`EXIT_OK` success, :data:`EXIT_BAD_INPUT` bad input (one
line on stderr naming the problem and what is allowed; ``--debug`` shows the traceback),
:data:`EXIT_FAILURE` unexpected failure, :data:`EXIT_INTERRUPTED` interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

import numpy as np

from fault_tolerance.errors import InvalidInput, RobotNotFound

if TYPE_CHECKING:
    from fault_tolerance.model.arm import Arm

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130

FORMATTER = argparse.RawDescriptionHelpFormatter


def epilog(example: str) -> str:
    """The ``example:`` block at the end of a command's ``--help``."""
    return "example:\n  " + example


def floats(text: str, what: str) -> np.ndarray:
    """Comma-separated finite numbers of option ``what``, or :class:`InvalidInput`."""
    try:
        vals = np.array([float(v) for v in text.replace(" ", "").split(",") if v != ""])
    except ValueError:
        raise InvalidInput(f"{what} must be comma-separated numbers, got '{text}'") from None
    if not len(vals) or not np.all(np.isfinite(vals)):
        raise InvalidInput(f"{what} must be finite comma-separated numbers, got '{text}'")
    return vals


def names(text: str | None) -> list[str] | None:
    """Comma-separated names (blanks dropped); ``None`` stays ``None``."""
    if text is None:
        return None
    return [t.strip() for t in text.split(",") if t.strip()]


# -- common robot options -------------------------------------------------------------------


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """``--robot | --description PATH [--package-dir DIR]``, ``--tip``, ``--task``, ``--joints``, ``--lockable``."""
    g = p.add_argument_group("robot")
    src = g.add_mutually_exclusive_group()
    src.add_argument(
        "--robot",
        default=None,
        help="shipped or example-robot-data arm (see `fault-tolerance robots`)",
    )
    add_description_option(src)
    add_source_options(g)
    g.add_argument(
        "--tip", default=None, help="tip frame (default: the catalog's, or the last frame)"
    )
    g.add_argument(
        "--task",
        default=None,
        help="planar | position | pose | rows among x,y,z,rx,ry,rz (default: the catalog's for "
        "a shipped or preset arm, else position)",
    )
    g.add_argument("--joints", default=None, help="active joints, comma-separated (others fixed)")
    g.add_argument(
        "--lockable",
        default=None,
        help="joints that may lock: all | none | joint2,joint3 | joint1+joint2,joint3 (+ joins a "
        "multi-joint scenario; none: only where a command can run without them) (default: the "
        "shipped arm's set (robots/catalog.json), else every active joint)",
    )


DESCRIPTION_HELP = (
    "path of a robot description: URDF (.urdf, or .xml with <robot>), xacro (.xacro, "
    ".urdf.xacro) or MuJoCo MJCF (.xml with <mujoco>); --urdf PATH is an alias"
)


def add_description_option(group, help_text: str = DESCRIPTION_HELP) -> None:
    """``--description PATH`` with its alias ``--urdf`` (one destination, ``args.description``)."""
    group.add_argument(
        "--description", "--urdf", dest="description", default=None, metavar="PATH", help=help_text
    )


def add_source_options(g) -> None:
    """``--package-dir`` and ``--xacro-arg`` (both repeatable)."""
    g.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="folder of the ROS packages named by package://pkg or $(find pkg): DIR/pkg, a DIR "
        "whose package.xml names pkg, or a workspace with pkg below it (repeatable)",
    )
    g.add_argument(
        "--xacro-arg",
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="argument of a xacro file (repeatable)",
    )


def load_robot(args) -> Arm:
    """The arm the robot options describe."""
    from fault_tolerance.model.formats.xacro import parse_xacro_args
    from fault_tolerance.model.loading import load_arm

    if args.robot is None and args.description is None:
        raise InvalidInput(
            "name a robot with --robot NAME or --description PATH (URDF, xacro or MJCF; see "
            "`fault-tolerance robots`)"
        )
    from fault_tolerance.cli.suits import robot_not_found

    try:
        return load_arm(
            args.description or args.robot,
            tip=args.tip,
            task=args.task,
            joints=names(args.joints),
            package_dirs=args.package_dir or None,
            xacro_args=parse_xacro_args(args.xacro_arg) or None,
        )
    except RobotNotFound as err:
        raise robot_not_found(err, getattr(args, "command", None)) from None


NONE_SUITS = (
    "--lockable none suits `lock --algorithm lnva` (rates that anticipate no failure; only the "
    "locking joint is measured)"
)


def lockable_of(args, arm, none_ok: bool = False):
    """Lockable joints from ``--lockable`` (``a+b`` is a two-joint scenario); arm default if absent.

    ``none`` (no joint expected to lock) gives ``[]`` where the command can run without lockable
    joints (``none_ok``); elsewhere it is refused with the reason.
    """
    if args.lockable is None:
        return list(arm.default_lockable)
    if args.lockable.strip() == "all":
        return list(arm.joint_names)
    if args.lockable.strip().lower() == "none":
        if none_ok:
            return []
        command = getattr(args, "command", None) or "this command"
        raise InvalidInput(
            f"--lockable none: `{command}` plans or measures for the joints that may lock and "
            f"needs at least one; name them (joint2,joint3) or use 'all'. {NONE_SUITS}"
        )
    items = []
    for tok in names(args.lockable) or []:
        items.append(tuple(tok.split("+")) if "+" in tok else tok)
    if not items:
        raise InvalidInput(
            "--lockable is empty; use 'all', 'none' or joint names like joint2,joint3"
        )
    return items


# -- units: --deg --------------------------------------------------------------------------

#: What ``--deg`` converts, and what not (every command's ``--help`` says it).
DEG_NOTE = (
    "angles of revolute and continuous joints are read in degrees and converted to radians; "
    "entries of prismatic joints are metres and are not converted. Never converted: rates "
    "[rad/s] (--omega), lengths, gains, times (docs/units.md)"
)


def add_deg_option(g, converts: str) -> None:
    """``--deg``: the angle options ``converts`` (named in its help) are read in degrees."""
    g.add_argument(
        "--deg",
        action="store_true",
        help=f"read {converts} in degrees (default: radians): {DEG_NOTE}",
    )


def joint_values(text: str, what: str, arm, deg: bool = False) -> np.ndarray:
    """One number per joint of option ``what`` [rad or m]; ``deg``: angular joints' in degrees."""
    from fault_tolerance.model.joint_limits import degrees_to_radians

    v = arm.check_q(floats(text, what), what)  # one per joint, or the error names the joints
    return degrees_to_radians(arm, v) if deg else v


def joint_ranges(text: str, what: str, arm, deg: bool = False) -> np.ndarray:
    """``lo:hi`` per joint of option ``what``, (n, 2) [rad or m]; ``deg`` as :func:`joint_values`."""
    from fault_tolerance.model.joint_limits import degrees_to_radians

    try:
        lim = np.array(
            [[float(v) for v in p.split(":")] for p in text.replace(" ", "").split(",") if p]
        )
    except ValueError:
        lim = np.zeros((0, 0))
    if lim.ndim != 2 or lim.shape[1] != 2 or not np.all(np.isfinite(lim)):
        raise InvalidInput(f"{what} must be finite lo:hi pairs, comma-separated, got '{text}'")
    if len(lim) != arm.n:
        raise InvalidInput(
            f"{what} has {len(lim)} lo:hi pairs; {arm.name} has {arm.n} joints {arm.joint_names}"
        )
    return degrees_to_radians(arm, lim) if deg else lim


def task_values(text: str, what: str, arm, deg: bool = False) -> np.ndarray:
    """Task coordinates of option ``what`` [m, rad]; ``deg``: the rows rx, ry, rz in degrees.

    An orientation row beyond a full turn (|value| > 2π rad) is refused, with the degrees hint
    when ``deg`` is off.
    """
    from fault_tolerance.model.joint_limits import DEGREES_OPTION_HINT

    v = floats(text, what)
    if len(v) != arm.m:
        raise InvalidInput(f"{what} has {len(v)} numbers; task {'/'.join(arm.task)} needs {arm.m}")
    ang = np.array([r.startswith("r") for r in arm.task], dtype=bool)
    if deg:
        v[ang] = np.deg2rad(v[ang])
    beyond = [i for i in np.flatnonzero(ang) if abs(v[i]) > 2 * np.pi]
    if beyond:
        rows = ", ".join(f"{arm.task[i]} = {v[i]:.6g} rad" for i in beyond)
        hint = "" if deg else f"; {DEGREES_OPTION_HINT}"
        raise InvalidInput(
            f"{what} has orientation rows beyond a full turn (|value| > 2π rad): {rows}{hint}"
        )
    return v


def dh_params_from_degrees(params, table, text: str) -> tuple:
    """``--deg`` of ``design --vary dh``: the angles of ``--params`` (``text``) from degrees.

    ``theta`` and ``alpha`` are angles; ``lower`` and ``upper`` are angles of revolute joints and
    metres of prismatic ones (not converted), ``a`` and ``d`` metres. Multiples of ``pi`` are
    refused with ``--deg`` (they are radians).
    """
    from dataclasses import replace

    if "pi" in text.lower():
        raise InvalidInput(
            f"--params {text!r} with --deg: write its angles in degrees (alpha2:{{0|90|-90}}), "
            "not as multiples of pi (radians)"
        )
    out = []
    for p in params:
        kind = table.joints[p.joint - 1].kind if p.joint <= table.n else "prismatic"
        if p.field in ("theta", "alpha") or (p.field in ("lower", "upper") and kind == "revolute"):
            p = replace(
                p,
                lo=float(np.deg2rad(p.lo)),
                hi=float(np.deg2rad(p.hi)),
                choices=tuple(float(np.deg2rad(c)) for c in p.choices),
            )
        out.append(p)
    return tuple(out)


def start_line(arm, q0, origin: str, deg: bool = False) -> str:
    """``start: q0 = [...] rad (origin)``, and the same in degrees with ``deg``.

    In the degrees list, prismatic joints' entries stay metres (named at the end).
    """
    from fault_tolerance.model.joint_limits import angular_columns

    q0 = np.asarray(q0, dtype=float)
    line = f"start: q0 = {np.round(q0, 4).tolist()} rad"
    if deg:
        ang = angular_columns(arm)
        shown = np.where(ang, np.rad2deg(q0), q0)
        linear = [arm.joint_names[i] for i in np.flatnonzero(~ang)]
        line += f" = {np.round(shown, 3).tolist()} deg" + (
            f" ({', '.join(linear)} in m)" if linear else ""
        )
    return f"{line} ({origin})"


# -- start, path ----------------------------------------------------------------------------


def add_path_options(p: argparse.ArgumentParser) -> None:
    """Start (``--x0`` / ``--q0``), path (circle or ``--csv``), time step and duration."""
    g = p.add_argument_group("start and path")
    g.add_argument(
        "--x0",
        default=None,
        help="start point (task coordinates [m; rad for rx,ry,rz, degrees with --deg]); the "
        "start posture is the minimum-RCN one. Without "
        "--x0 and --q0 a start is chosen that is inside the limits, regular, with every lockable "
        "joint tolerable, and runs the task cleanly (docs/MATH.md, 'The default start'); it is "
        "printed",
    )
    g.add_argument(
        "--q0",
        default=None,
        help="start configuration, one number per joint [rad; m for prismatic joints; degrees "
        "with --deg], used as given (a full-turn joint modulo 2π into its limits) and printed; "
        "it must be inside the joint limits (any angle beyond a turn, 2π·1.01, is refused even "
        "with --no-limits: it looks like degrees)",
    )
    add_deg_option(g, "--q0 and the orientation rows of --x0")
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
        "--omega",
        type=float,
        default=None,
        help="circle angular rate [rad/s] (default 2π; --deg does not "
        "convert it: the rate of the circle's parameter, not a joint or orientation angle)",
    )
    g.add_argument(
        "--rows",
        default=None,
        help="the two task rows the circle lies in, e.g. x,y or y,z (default: the "
        "catalog's for a shipped arm, else the first two task rows)",
    )
    g.add_argument("--dt", type=float, default=1e-3, help="time step [s] (default 0.001)")
    g.add_argument(
        "--duration", type=float, default=None, help="run length [s] (default: the path's)"
    )
    g.add_argument(
        "--feedback",
        type=float,
        default=None,
        help="task-space feedback gain K_p [1/s] (default: 0 for simulate, as in the paper; "
        "10 for lock)",
    )
    g.add_argument(
        "--response",
        default="least_norm",
        choices=["least_norm", "continuation"],
        help="post-failure response of the reduced robot (docs/MATH.md, G3)",
    )
    from fault_tolerance.resolution.mda import MDA_GAIN

    g.add_argument("--gain", type=float, default=None, help=f"MDA gain α (default: {MDA_GAIN:g})")
    g.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="an option of the resolver (its options dataclass; docs/architecture.md, 'Adding a "
        "resolver'), e.g. --option damping=0.05; repeat for several. Each algorithm gets the "
        "options it takes; one that none of them takes is refused",
    )
    g.add_argument(
        "--no-limits",
        action="store_true",
        help="ignore the joint position and velocity limits (the paper's formulation): a --q0 "
        "outside them is then allowed, but not beyond a turn (docs/units.md); by default every "
        "step stays inside them (docs/MATH.md, Joint limits)",
    )


def _option_value(text: str):
    """``--option`` values: a number, true/false, none, or the text itself."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    if low == "none":
        return None
    try:
        return int(text) if low.lstrip("+-").isdigit() else float(text)
    except ValueError:
        return text.strip()


#: Resolver options that have a flag of their own (option name -> flag); --option refuses them
#: when the flag is given too.
OPTION_FLAGS = {"gain": "--gain", "response": "--response"}


def _refuse_set_twice(args, name: str, item: str, given: dict) -> None:
    """``--option NAME=...`` whose NAME was set before, by ``--option`` or by its own flag."""
    if name in given:
        raise InvalidInput(f"--option {name} given twice ({name}={given[name]!r} and {item!r}); "
                           "give it once")  # fmt: skip
    flag = OPTION_FLAGS.get(name)
    if flag and flag.lstrip("-") in getattr(args, "given_options", ()):
        raise InvalidInput(f"{flag} and --option {item!r} set the same option; give one of them")


def resolver_options(args, algorithms) -> dict:
    """``--option NAME=VALUE`` as a dict; an option none of ``algorithms`` takes is refused.

    So is a NAME given twice, or given with its own flag too (:data:`OPTION_FLAGS`).
    """
    from fault_tolerance.simulation.simulate import option_names

    given: dict = {}
    for item in getattr(args, "option", None) or []:
        name, eq, value = item.partition("=")
        if not eq or not name.strip():
            raise InvalidInput(f"--option {item!r}: write NAME=VALUE, e.g. --option gain=0.02")
        _refuse_set_twice(args, name.strip(), item, given)
        given[name.strip()] = _option_value(value)
    taken = {k for a in algorithms for k in option_names(a)}
    unknown = sorted(set(given) - taken)
    if unknown:
        allowed = {a: list(option_names(a)) for a in algorithms}
        raise InvalidInput(
            f"--option {unknown}: not an option of {list(algorithms)}; theirs: {allowed}"
        )
    return given


def limits_line(run_) -> str:
    """One line on what the joint limits did in a run."""
    s = run_.summary()
    if not s.get("limits"):
        return (
            "joint limits: off (--no-limits); samples outside the position limits "
            f"{s.get('outside_position_limits_samples', '?')}, over a velocity limit "
            f"{s.get('over_velocity_limit_samples', '?')}"
        )
    return (
        f"joint limits: on (rate box, horizon {run_.meta['limits']['horizon']:g} s): "
        f"{s['bound_active_samples']} samples with an active bound, {s['task_scaled_samples']} "
        f"with a scaled task, {s['intolerable_under_limits_samples']} where a lock would be "
        "intolerable under limits; outside the position limits "
        f"{s['outside_position_limits_samples']}, over a velocity limit "
        f"{s['over_velocity_limit_samples']}"
    )


def bar(total: int, enabled: bool, desc: str):
    """A tqdm progress bar of ``total`` steps, or ``None`` when not ``enabled``."""
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="step", desc=desc)


def _default_text(action: argparse.Action) -> str:
    """How ``--help`` states an option's default when its help does not say it."""
    d = action.default
    if isinstance(action, argparse._StoreTrueAction):
        return "off"
    if d is None or d == []:
        return "none"
    if isinstance(d, float):
        return f"{d:g}"
    return str(d)


def state_defaults(parser: argparse.ArgumentParser) -> None:
    """Give every option of ``parser`` and its sub-commands a help text that states its default.

    An option whose help already says ``default`` keeps it; the others get ``(default: X)``.
    """
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                state_defaults(sub)
            continue
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue
        if isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            continue
        text = action.help or ""
        if action.required:  # a required option has no default: say it is required
            if "required" not in text.lower():
                text = f"{text} (required)".strip()
        elif "default" not in text.lower():
            text = f"{text} (default: {_default_text(action)})".strip()
        action.help = text


def close_bars() -> None:
    """Close every progress bar still drawn, so what is printed next starts on its own line.

    A closed bar is drawn once more, finished, with its newline, and never redrawn: an error
    raised while a bar is drawn then appears on a line of its own, once.
    """
    if "tqdm" not in sys.modules:
        return
    from tqdm.std import tqdm

    for b in list(getattr(tqdm, "_instances", ())):
        b.close()


def report_warnings(command: str, label: str, run_, arm) -> list[dict]:
    """Print one line on stderr per problem :mod:`~fault_tolerance.simulation.diagnostics` finds in ``run_``.

    Returns the warnings as dicts for summary.json (``Run.save(..., warnings=...)``).
    """
    from fault_tolerance.simulation.diagnostics import check_run, warning_lines

    found = check_run(run_, arm)
    for line in warning_lines(label, found):
        print(f"fault-tolerance {command}: {line}", file=sys.stderr)
    return [w.as_dict() for w in found]
