"""``fault-tolerance warm``: compile the fast path into the cache now, in the foreground."""

from __future__ import annotations

import argparse

from fault_tolerance.cli.common import FORMATTER, epilog

NAME = "warm"
HELP = "compile the fast path once, so later commands start compiled"
EXAMPLE = "fault-tolerance warm\n  fault-tolerance warm controller bounded simulate"


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``warm`` sub-command."""
    from fault_tolerance.bench.warm import GROUPS

    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument(
        "groups",
        nargs="*",
        metavar="GROUP",
        help=f"kernel groups to compile, among {', '.join(GROUPS)} (default: every group)",
    )
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """Compile the cold groups (unknown ones refused by :func:`warm`); say what and where."""
    from fault_tolerance.bench.warm import GROUPS, warm
    from fault_tolerance.fast_cache import cache_folder

    done = warm(args.groups or list(GROUPS))
    what = f"compiled {', '.join(done)}" if done else "nothing to compile"
    folder = cache_folder()
    where = folder if folder.is_dir() else "numba's own (that folder cannot be written)"
    print(f"{what}; the compiled cache is {where}")
    return 0
