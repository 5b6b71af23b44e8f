"""``fault-tolerance replay``: meshcat replay of a saved run."""

from __future__ import annotations

import argparse

from fault_tolerance.cli.common import FORMATTER, epilog

NAME = "replay"
HELP = "meshcat replay of a saved run"
EXAMPLE = (
    "fault-tolerance replay out/fig2/jvja --html replay.html\n"
    "  fault-tolerance replay out/fig2/jvja --open"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``replay`` sub-command."""
    s = sub.add_parser(NAME, help=HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER)
    s.add_argument("run", help="folder of a saved run (with run.npz)")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--open", action="store_true", help="serve it on 127.0.0.1 and print the URL")
    g.add_argument("--html", default=None, help="write one self-contained HTML file")
    s.add_argument("--speed", type=float, default=1.0, help="playback speed factor (default 1)")
    s.add_argument(
        "--package-dir",
        action="append",
        default=[],
        help="folder (or workspace) where meshes of the run's arm may be read (repeatable); no other "
        "file is opened: the arm is rebuilt from the URDF text the run carries",
    )
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """Meshcat replay of a saved run."""
    from fault_tolerance.viz import replay_main

    return replay_main(
        args.run,
        open=args.open,
        html=args.html,
        speed=args.speed,
        package_dirs=args.package_dir,
    )
