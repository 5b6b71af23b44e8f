"""``fault-tolerance robots``: list shipped and example-robot-data arms."""

from __future__ import annotations

import argparse
import textwrap

from fault_tolerance.cli.common import FORMATTER, epilog
from fault_tolerance.errors import FaultToleranceError

NAME = "robots"
HELP = "list shipped and example-robot-data arms"
EXAMPLE = "fault-tolerance robots\n  fault-tolerance robots --all"


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``robots`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument(
        "--all",
        action="store_true",
        help="also list every model example-robot-data can load, by name (most are not arms: "
        "legged robots, hands; load one with --robot NAME --tip FRAME) (default: off)",
    )
    s.set_defaults(func=run)
    return s


def _row(name: str, source: str, arm, description: str) -> tuple:
    return (name, source, arm.n, "/".join(arm.task), arm.m, arm.redundancy, description)


def run(args) -> int:
    """List shipped and example-robot-data arms."""
    from fault_tolerance.model.catalog import EXAMPLE_ROBOTS, catalog
    from fault_tolerance.model.loading import load_arm

    rows = [
        _row(name, "shipped", load_arm(name), e["description"]) for name, e in catalog().items()
    ]
    for name, preset in EXAMPLE_ROBOTS.items():
        try:
            arm = load_arm(name)
        except FaultToleranceError as err:  # pragma: no cover - depends on the installed data
            rows.append((name, "example-robot-data", "?", "?", "?", "?", f"unavailable: {err}"))
            continue
        rows.append(_row(name, "example-robot-data", arm, preset["description"]))
    head = ("name", "source", "DOF", "task", "m", "r", "description")
    widths = [max(len(str(r[i])) for r in rows + [head]) for i in range(len(head))]
    for r in [head] + rows:
        print("  ".join(str(v).ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    print(
        "\nAny other example-robot-data name or a URDF, xacro or MJCF path works too "
        "(--robot NAME | --description PATH)."
    )
    if args.all:
        from fault_tolerance.model.catalog import example_robot_names

        others = [n for n in example_robot_names() if n not in EXAMPLE_ROBOTS]
        print(f"\nexample-robot-data models without a preset ({len(others)}):")
        print("\n".join(textwrap.wrap(", ".join(others), 100)))
    return 0
