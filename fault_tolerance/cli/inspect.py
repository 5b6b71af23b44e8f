"""``fault-tolerance inspect``: kinematic tree, chosen chain and task, intolerable joints."""

from __future__ import annotations

import argparse

from .common import FORMATTER, epilog, names

NAME = "inspect"
HELP = "kinematic tree, chosen chain and task, intolerable joints"
EXAMPLE = "fault-tolerance inspect spatial_4r\n  fault-tolerance inspect my_arm.urdf --tip tool0"


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``inspect`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument("target", help="shipped / example-robot-data name or URDF path")
    s.add_argument("--tip", default=None)
    s.add_argument("--task", default=None)
    s.add_argument("--joints", default=None)
    s.add_argument("--package-dir", action="append", default=[])
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """Print the kinematic tree, the chosen chain and task, and intolerable joints."""
    from ..inspection import inspect_text

    print(
        inspect_text(
            args.target,
            tip=args.tip,
            task=args.task,
            joints=names(args.joints),
            package_dirs=args.package_dir or None,
        )
    )
    return 0
