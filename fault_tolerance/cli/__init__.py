"""The ``fault-tolerance`` command: one module per sub-command, shared options in :mod:`.common`.

Each command module has ``NAME``, ``HELP``, ``EXAMPLE``, ``add_parser(subparsers)`` and
``run(args) -> exit code``; :data:`COMMANDS` lists them in the order ``--help`` shows. A new
command is a new module added to that list.

Exit codes: 0 success, 2 bad input (one line on stderr naming the problem and what is allowed;
``--debug`` shows the traceback), 1 unexpected failure, 130 interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import sys
import textwrap

from fault_tolerance.cli import (
    bench,
    design,
    inspect,
    lock,
    replay,
    reproduce,
    robots,
    simulate,
    warm,
    workspace,
)
from fault_tolerance.cli.common import FORMATTER, state_defaults
from fault_tolerance.cli.runner import Parser, run_command
from fault_tolerance.version import __version__

__all__ = [
    "COMMANDS",
    "EXAMPLES",
    "build_parser",
    "main",
]

#: The sub-command modules, in the order of ``fault-tolerance --help``.
COMMANDS = [robots, inspect, simulate, lock, reproduce, replay, workspace, design, bench, warm]
#: The ``example:`` text of each command's ``--help``.
EXAMPLES = {mod.NAME: mod.EXAMPLE for mod in COMMANDS}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``fault-tolerance``."""
    p = Parser(
        prog="fault-tolerance",
        formatter_class=FORMATTER,
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
    for mod in COMMANDS:
        mod.add_parser(sub)
    state_defaults(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    return run_command(args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
