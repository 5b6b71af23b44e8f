"""The ``workspace`` and ``design`` commands (sweeps, serial or on Dask)."""

from __future__ import annotations

import argparse
import time

from .errors import InvalidInput

EXAMPLES = {
    "workspace": (
        "fault-tolerance workspace --robot planar_3r --limits=-60:60,-120:120,-120:120 --deg "
        "--out out/ws\n"
        "  fault-tolerance workspace --robot powercube_3r --grid 301 --workers 2 --out out/pc\n"
        "  fault-tolerance workspace --robot spatial_4r --grid 24 --scheduler tcp://10.0.0.5:8786 "
        "--out out/4r"
    ),
    "design": (
        "fault-tolerance design --robot planar_3r --vary limits --objective ftw-area --out out/d\n"
        "  fault-tolerance design --robot planar_3r --vary links,limits --objective jvj "
        "--rcn-max 40 --task circle --workers 2 --out out/d_jvj"
    ),
}
DASK_HELP = (
    "dask: --workers N starts a local cluster of N processes on 127.0.0.1 (1: in this process, "
    "0: serial without Dask); --scheduler tcp://HOST:PORT uses a running cluster (`dask "
    "scheduler` on one machine, `dask worker tcp://HOST:PORT --nthreads 1` on each, with "
    "fault_tolerance installed). Finished chunks go to OUT/chunks-<hash>/; a rerun of the same "
    "command resumes from them, and Ctrl-C keeps them."
)


def _dask_options(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    g.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true")


def _singletons(lockable) -> list[str]:
    if any(isinstance(j, tuple) for j in lockable):
        raise InvalidInput("sweeps lock one joint at a time; use --lockable joint1,joint2 (no +)")
    return list(lockable)


def add_parsers(sub, fmt, add_robot_options) -> None:
    """Add ``workspace`` and ``design`` to the subcommand parser ``sub``."""
    s = sub.add_parser(
        "workspace",
        help="failure-tolerant workspace map (areas/volumes, jump and RCN maps)",
        description=DASK_HELP,
        epilog="example:\n  " + EXAMPLES["workspace"],
        formatter_class=fmt,
    )
    add_robot_options(s)
    s.add_argument("--limits", default=None, help="artificial limits lo:hi per joint, written --limits=-1:1,... (default: URDF)")
    s.add_argument("--deg", action="store_true", help="--limits in degrees")
    s.add_argument("--grid", type=int, default=None, help="points per axis (planar 201, spatial 24)")
    s.add_argument("--samples", type=int, default=None, help="self-motion / configuration samples")
    s.add_argument("--theta-samples", type=int, default=None, help="sampled lock angles")
    s.add_argument("--chunks", type=int, default=None, help="chunks of a planar map (default 16)")
    _dask_options(s)
    s.set_defaults(func=cmd_workspace)

    s = sub.add_parser(
        "design",
        help="artificial limits (and links) of a planar 3R for fault tolerance",
        description=DASK_HELP,
        epilog="example:\n  " + EXAMPLES["design"],
        formatter_class=fmt,
    )
    add_robot_options(s)
    s.add_argument("--vary", default="limits", help="limits | links,limits (default limits)")
    s.add_argument("--objective", default="ftw-area", help="ftw-area | jvj | rcn")
    s.add_argument("--x0", default=None, help="circle start x,y [m]")
    s.add_argument("--radius", type=float, default=None, help="circle radius [m]")
    s.add_argument("--rcn-max", type=float, default=None, help="require max K <= this on the task")
    s.add_argument("--candidates", type=int, default=128, help="quasi-random designs (default 128)")
    s.add_argument("--rounds", type=int, default=4, help="pattern-search rounds (default 4)")
    s.add_argument("--grid", type=int, default=201, help="grid of the chosen design's map")
    s.add_argument("--seed", type=int, default=0)
    _dask_options(s)
    s.set_defaults(func=cmd_design)


def cmd_workspace(args) -> int:
    """Failure-tolerant workspace of one arm into ``--out``."""
    from .cli.common import load_robot, lockable_of
    from .workspace import failure_tolerant_workspace

    arm = load_robot(args)
    opts = {k: v for k in ("grid", "samples", "theta_samples", "chunks")
            if (v := getattr(args, k)) is not None}
    t0 = time.perf_counter()
    ws = failure_tolerant_workspace(
        arm, args.limits, _singletons(lockable_of(args, arm)), deg=args.deg,
        workers=args.workers or 0, scheduler=args.scheduler, folder=args.out,
        progress=not args.no_progress, **opts,
    )
    ws.save(args.out)
    unit, kind = ("m³", "volume") if ws.spatial else ("m²", "area")
    print(
        f"{arm.name}: {kind} before a failure {ws.size_pre:.4g} {unit}, failure tolerant "
        f"{ws.size_ftw:.4g} {unit} ({ws.spec['method']}, grid {ws.spec['grid']}, "
        f"{time.perf_counter() - t0:.1f} s) -> {args.out}/workspace.json, .npz, .png"
    )
    return 0


def cmd_design(args) -> int:
    """Design search into ``--out``: design.json and design.png."""
    import numpy as np

    from .cli.common import floats as _floats
    from .cli.common import load_robot, lockable_of
    from .design import Task, default_task
    from .design_search import design

    if args.task not in (None, "circle", "planar"):  # design's --task names the task path
        raise InvalidInput(
            f"--task '{args.task}' is not one of ['circle'] (design's task is the circle path; "
            "the robot's task rows are planar)"
        )
    args.task = "planar"
    arm = load_robot(args)
    arm.default_lockable = _singletons(lockable_of(args, arm))
    task = default_task(arm) if arm.n == 3 else None
    if task is not None and (args.x0 is not None or args.radius is not None):
        x0 = tuple(_floats(args.x0, "--x0")) if args.x0 else task.x0
        task = Task(x0, args.radius or task.radius, task.omega, task.duration, task.sign)
        if len(x0) != 2 or not np.isfinite(task.radius) or task.radius <= 0:
            raise InvalidInput("--x0 needs two numbers x,y and --radius a positive number [m]")
    d = design(
        arm, args.vary, args.objective, task=task, rcn_max=args.rcn_max,
        candidates=args.candidates, rounds=args.rounds, grid=args.grid, seed=args.seed,
        workers=args.workers or 0, scheduler=args.scheduler, folder=args.out,
        progress=not args.no_progress,
    )
    d.save(args.out)
    r = d.record
    fmt = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
    print(
        f"{arm.name}: {r['objective']} design, limits [rad] {np.round(r['limits'], 3).tolist()}"
        + (f", links [m] {np.round(r['links'], 4).tolist()}" if "links" in r else "")
        + f"; FTW area {r['area_ftw']:.4g} m², mean JVJ {fmt(r['jvj'])}, mean K {fmt(r['rcn'])} "
        f"({r['evaluations']} designs, {r['elapsed_s']} s) -> {args.out}/design.json"
    )
    return 0
