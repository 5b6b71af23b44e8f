"""``fault-tolerance reproduce``: every case of the paper (figures, summary.json, REPORT.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fault_tolerance.cli.common import EXIT_INTERRUPTED, FORMATTER, epilog, names, start_line
from fault_tolerance.errors import InvalidInput

NAME = "reproduce"
HELP = "every case of the paper: figures, summary.json, REPORT.md"
EXAMPLE = (
    "fault-tolerance reproduce --out reproduce_out\n"
    "  fault-tolerance reproduce --out quick --quick --cases fig2,experiment"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``reproduce`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument("--out", default="reproduce_out", help="output folder (default reproduce_out)")
    s.add_argument("--cases", default=None, help="subset, e.g. fig2,fig4,experiment")
    s.add_argument("--quick", action="store_true", help="shortened runs (for tests)")
    s.add_argument("--html", action="store_true", help="also write meshcat replays (replay.html)")
    s.add_argument(
        "--no-beyond",
        action="store_true",
        help="skip the section 'beyond the paper' (the whole-path plan on every case)",
    )
    s.add_argument(
        "--no-progress", action="store_true", help="no progress bar (default: the bar is shown)"
    )
    s.set_defaults(func=run)
    return s


#: The kernel groups the paper's runs call (:mod:`fault_tolerance.bench.warm`).
REPRODUCE_KERNELS = ("controller", "bounded", "simulate")


def run(args) -> int:
    """Every case of the paper into --out."""
    from fault_tolerance.paper.reproduce import reproduce

    cases = names(args.cases)
    if cases == []:
        raise InvalidInput(
            f"--cases {args.cases!r} names no case; give a subset like fig2,experiment or leave "
            "--cases out for all"
        )
    out = Path(args.out)
    from fault_tolerance.bench.warm import compile_ahead, warm

    if compile_ahead():  # what the runs call, once (one line on stderr): no kernel it does not call
        warm(REPRODUCE_KERNELS)
    try:
        summary = reproduce(
            out,
            cases=cases,
            quick=args.quick,
            progress=not args.no_progress,
            html=args.html,
            beyond=not args.no_beyond,
        )
    except KeyboardInterrupt:
        print(
            f"interrupted: finished cases are in {out}; see {out / 'summary.partial.json'} for what "
            "was not finished (an earlier summary.json is left as it was)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    for case, c in summary.get("cases", {}).items():  # every case's start, as simulate prints it
        if c.get("q0") is not None:
            print(start_line(None, c["q0"], f"{case}, {c.get('robot', '?')}"))
    for w in summary.get("warnings", []):
        print(f"fault-tolerance reproduce: warning: {w['run']}: {w['message']}", file=sys.stderr)
    print(
        f"wrote {out}/summary.json, {out}/REPORT.md and figures in {summary['meta']['seconds']} s"
    )
    return 0
