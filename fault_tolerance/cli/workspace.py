"""``fault-tolerance workspace``: the failure-tolerant workspace of one arm (a sweep, on Dask)."""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path

from fault_tolerance.cli.common import (
    FORMATTER,
    add_deg_option,
    add_robot_options,
    epilog,
    joint_ranges,
    load_robot,
    lockable_of,
)
from fault_tolerance.errors import InvalidInput

NAME = "workspace"
HELP = "failure-tolerant workspace map (areas/volumes, jump and RCN maps)"
EXAMPLE = (
    "fault-tolerance workspace --robot planar_3r --limits=-60:60,-120:120,-120:120 --deg "
    "--out out/ws\n"
    "  fault-tolerance workspace --robot powercube_3r --grid 301 --workers 2 --out out/pc\n"
    "  fault-tolerance workspace --robot spatial_4r --grid 24 --scheduler tcp://10.0.0.5:8786 "
    "--out out/4r"
)
DASK_HELP = (
    "dask: --workers N starts a local cluster of N processes on 127.0.0.1 (1: in this process, "
    "0: serial without Dask); --scheduler tcp://HOST:PORT uses a running cluster (`dask "
    "scheduler` on one machine, `dask worker tcp://HOST:PORT --nthreads 1` on each, with "
    "fault_tolerance installed). Finished chunks go to OUT/chunks-<hash>/; a rerun of the same "
    "command resumes from them, and Ctrl-C keeps them."
)


def add_dask_options(p: argparse.ArgumentParser) -> None:
    """``--workers N | --scheduler ADDR``, ``--out DIR``, ``--no-progress`` (the sweeps' options)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--workers",
        type=int,
        default=1,
        help="local worker processes (default 1: one worker in this process; 0: serial)",
    )
    g.add_argument(
        "--scheduler",
        default=None,
        help="address of a running Dask scheduler (default: a local cluster of --workers)",
    )
    p.add_argument("--out", required=True, help="output folder (required; default: none)")
    p.add_argument(
        "--no-progress", action="store_true", help="no progress bar (default: the bar is shown)"
    )


@contextlib.contextmanager
def sweep_output(out: str, replaceable: tuple[str, ...]) -> Iterator[Path]:
    """Check ``--out`` before any work, lock it, and leave no folder behind if the command fails.

    ``--out`` must be a folder or absent (not a file, a link, nor a path under a file); an
    existing one may hold only a result of this command and its ``chunks-*/``. On failure the
    folders this command created and left empty are removed (finished chunks are kept).
    """
    from fault_tolerance.storage.folder_io import check_path_names, refuse_link
    from fault_tolerance.storage.folder_lock import FolderLock
    from fault_tolerance.storage.result_folder import check_target, created_folders

    path = check_path_names(Path(out))
    above = Path(os.path.abspath(path)).parent
    while not os.path.lexists(above) and above != above.parent:
        above = above.parent
    if not above.is_dir():
        raise InvalidInput(f"{out}: --out lies under {above}, which is not a folder")
    if os.path.lexists(path) and not os.path.islink(path) and not path.is_dir():
        raise InvalidInput(f"{out}: --out exists and is not a folder; choose a folder")
    refuse_link(path, folder=True)
    with created_folders(path), FolderLock(path):  # a second writer of --out exits 2
        check_target(path, (*replaceable, "chunks-*/*"))
        yield path


def singletons(lockable) -> list[str]:
    """The lockable joints of a sweep: one joint per scenario."""
    if any(isinstance(j, tuple) for j in lockable):
        raise InvalidInput("sweeps lock one joint at a time; use --lockable joint1,joint2 (no +)")
    return list(lockable)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``workspace`` sub-command."""
    s = sub.add_parser(
        NAME, help=HELP, description=DASK_HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER
    )
    add_robot_options(s)
    s.add_argument(
        "--limits",
        default=None,
        help="artificial limits lo:hi per joint [rad; m for prismatic joints; degrees with "
        "--deg], written --limits=-1:1,... (default: URDF)",
    )
    add_deg_option(s, "--limits")
    s.add_argument(
        "--grid",
        type=int,
        default=None,
        help="points per axis (default: 201 for a planar 3R; sampled method: 101 for other "
        "planar arms, 24 for position tasks)",
    )
    s.add_argument(
        "--samples",
        type=int,
        default=None,
        help="joint-3 values of the self-motion for a planar 3R (default 120); configurations "
        "of the sampled method (default: 20000 planar, 40000 position)",
    )
    s.add_argument(
        "--theta-samples",
        type=int,
        default=None,
        help="lock angles per joint where the exact test does not apply (default: 181 for a "
        "planar 3R, 7 for the sampled method)",
    )
    s.add_argument(
        "--chunks",
        type=int,
        default=None,
        help="chunks of a planar-3R map, each a share of the radii (default 16); the sampled "
        "method chunks by 10000 configurations",
    )
    add_dask_options(s)
    s.set_defaults(func=run)
    return s


def run(args) -> int:
    """Failure-tolerant workspace of one arm into ``--out``."""
    from fault_tolerance.analysis.workspace.result import WORKSPACE_FILES

    with sweep_output(args.out, WORKSPACE_FILES):
        return _run(args)


def _run(args) -> int:
    from fault_tolerance.analysis.workspace.closed_form import failure_tolerant_workspace

    arm = load_robot(args)
    keys = ("grid", "samples", "theta_samples", "chunks")
    opts = {k: getattr(args, k) for k in keys if getattr(args, k) is not None}
    t0 = time.perf_counter()
    limits = None if args.limits is None else joint_ranges(args.limits, "--limits", arm)
    ws = failure_tolerant_workspace(
        arm,
        limits,
        singletons(lockable_of(args, arm)),
        deg=args.deg,  # converted and checked there: a refusal then says whether --deg was on
        workers=args.workers or 0,
        scheduler=args.scheduler,
        folder=args.out,
        progress=not args.no_progress,
        **opts,
    )
    from fault_tolerance.figures.workspace import plot_workspace

    ws.save(args.out, draw=plot_workspace)
    unit, kind = ("m³", "volume") if ws.spatial else ("m²", "area")
    print(
        f"{arm.name}: {kind} before a failure {ws.size_pre:.4g} {unit}, failure tolerant "
        f"{ws.size_ftw:.4g} {unit} ({ws.spec['method']}, grid {ws.spec['grid']}, "
        f"{time.perf_counter() - t0:.1f} s) -> {args.out}/workspace.json, .npz, .png"
    )
    return 0
