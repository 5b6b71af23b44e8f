"""``fault-tolerance bench``: the performance benchmark (options in :mod:`fault_tolerance.bench`)."""

from __future__ import annotations

import argparse

from fault_tolerance.cli.common import FORMATTER, epilog

NAME = "bench"
HELP = "the performance benchmark"
EXAMPLE = (
    "fault-tolerance bench\n"
    "  fault-tolerance bench --json old.json\n"
    "  fault-tolerance bench --json new.json\n"
    "  fault-tolerance bench --compare old.json new.json"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``bench`` sub-command."""
    from fault_tolerance.bench import command as bench

    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    bench.add_arguments(s)
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """The performance benchmark."""
    from fault_tolerance.bench import command as bench

    return bench.run(args)
