"""``fault-tolerance inspect``: kinematic tree, chosen chain and task, intolerable joints."""

from __future__ import annotations

import argparse

from fault_tolerance.cli.common import (
    FORMATTER,
    add_description_option,
    add_source_options,
    epilog,
    names,
)

NAME = "inspect"
HELP = "kinematic tree, chosen chain and task, intolerable joints"
EXAMPLE = (
    "fault-tolerance inspect spatial_4r\n  fault-tolerance inspect my_arm.urdf --tip tool\n"
    "  fault-tolerance inspect ur_description/urdf/ur5e.xacro --package-dir . --tip tool0"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``inspect`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument(
        "target",
        nargs="?",
        default=None,
        help="shipped / example-robot-data name, or a URDF, xacro or MJCF path (or --robot / "
        "--description, as in the other commands)",
    )
    src = s.add_mutually_exclusive_group()
    src.add_argument(
        "--robot", default=None, help="the same as TARGET, a robot name (default: none)"
    )
    add_description_option(
        src, "the same as TARGET, a URDF, xacro or MJCF file; --urdf is an alias (default: none)"
    )
    s.add_argument(
        "--tip",
        default=None,
        help="tip frame (a link); see the serial chains listed (default: the catalog's, or the "
        "last frame)",
    )
    s.add_argument(
        "--task",
        default=None,
        help="planar | position | pose | rows among x,y,z,rx,ry,rz (default: the catalog's, "
        "else position)",
    )
    s.add_argument(
        "--joints",
        default=None,
        help="active joints, comma-separated, others fixed (default: every joint of the chain "
        "to the tip)",
    )
    add_source_options(s)
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """Print the kinematic tree, the chosen chain and task, and intolerable joints."""
    from fault_tolerance.analysis.inspection import inspect_text
    from fault_tolerance.cli.suits import robot_not_found
    from fault_tolerance.errors import InvalidInput, RobotNotFound
    from fault_tolerance.model.formats.xacro import parse_xacro_args

    given = [t for t in (args.target, args.robot, args.description) if t is not None]
    if len(given) != 1:
        raise InvalidInput(
            "name one robot: fault-tolerance inspect NAME|PATH (or --robot NAME, --description "
            "PATH); "
            f"got {len(given)}"
        )
    try:
        text = inspect_text(
            given[0],
            tip=args.tip,
            task=args.task,
            joints=names(args.joints),
            package_dirs=args.package_dir or None,
            xacro_args=parse_xacro_args(args.xacro_arg) or None,
        )
    except RobotNotFound as err:
        raise robot_not_found(err, "inspect") from None
    print(text)
    return 0
