"""``fault-tolerance design``: limits and links of a planar 3R, or DH parameters of a spatial arm."""

from __future__ import annotations

import argparse

import numpy as np

from fault_tolerance.cli.common import (
    FORMATTER,
    add_robot_options,
    epilog,
    floats,
    load_robot,
    lockable_of,
)
from fault_tolerance.cli.design_dh import DH_ONLY, run_dh
from fault_tolerance.cli.design_dh import add_arguments as add_dh_arguments
from fault_tolerance.cli.workspace import DASK_HELP, add_dask_options, singletons, sweep_output
from fault_tolerance.errors import InvalidInput

NAME = "design"
HELP = "design for fault tolerance: planar 3R limits/links, or a spatial arm's DH parameters"
EXAMPLE = (
    "fault-tolerance design --robot planar_3r --vary limits --objective ftw-area --out out/d\n"
    "  fault-tolerance design --robot planar_3r --vary links,limits --objective jvj "
    "--rcn-max 40 --task circle --workers 2 --out out/d_jvj\n"
    "  fault-tolerance design --vary dh --dh spatial_4r --params d3:0.2:0.6,a4:0.1:0.5 "
    "--rcn-max 100 --out out/d_4r"
)


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``design`` sub-command (its ``--task`` names the task path: circle)."""
    s = sub.add_parser(
        NAME, help=HELP, description=DASK_HELP, epilog=epilog(EXAMPLE), formatter_class=FORMATTER
    )
    add_robot_options(s)
    _task_help(s)
    s.add_argument(
        "--vary",
        default="limits",
        help="limits | links,limits (planar 3R) | dh | dh,limits (a DH arm) (default limits)",
    )
    s.add_argument(
        "--objective",
        default=None,
        help="ftw-area | jvj | rcn for a planar 3R (default ftw-area); mean-jvj | max-jvj | "
        "manipulability | ftw-volume (sampled failure-tolerant volume) for --vary dh (default "
        "mean-jvj)",
    )
    s.add_argument(
        "--x0",
        default=None,
        help="circle start x,y [m] (x,y,z for --vary dh) (default: the catalog's)",
    )
    s.add_argument(
        "--radius", type=float, default=None, help="circle radius [m] (default: the catalog's)"
    )
    s.add_argument(
        "--rcn-max",
        type=float,
        default=None,
        help="require max K <= this on the task (default: no requirement); --vary dh: max k_S "
        "<= this (default 100, the paper's threshold)",
    )
    s.add_argument(
        "--candidates",
        type=int,
        default=None,
        help="planar 3R: designs asked of the first population (the baseline, then quasi-random "
        "ones); with d varied parameters it holds max(4, ceil(C/d))·d designs, C rounded up to "
        "a multiple of d and at least 4·d (default 128)",
    )
    s.add_argument("--rounds", type=int, default=4, help="pattern-search rounds (default 4)")
    s.add_argument(
        "--grid",
        type=int,
        default=None,
        help="planar 3R: grid of the chosen design's map (default 201)",
    )
    s.add_argument(
        "--seed", type=int, default=0, help="seed of the quasi-random designs (default 0)"
    )
    add_dask_options(s)
    add_dh_arguments(s)
    s.set_defaults(func=run)
    return s


def _task_help(s: argparse.ArgumentParser) -> None:
    """``--task`` of ``design`` names the task path, and only ``circle`` is one: say so."""
    action = next(a for a in s._actions if "--task" in a.option_strings)
    action.help = "the task path: circle, the only one ('planar' means the same) (default: circle)"
    action.metavar = "circle"


def _task(args, arm):
    from fault_tolerance.analysis.design.planar import Task, default_task

    task = default_task(arm) if arm.n == 3 else None
    if task is None or (args.x0 is None and args.radius is None):
        return task
    x0 = tuple(floats(args.x0, "--x0")) if args.x0 else task.x0
    radius = task.radius if args.radius is None else args.radius
    if len(x0) != 2 or not np.isfinite(radius) or radius <= 0:
        raise InvalidInput("--x0 needs two numbers x,y and --radius a positive number [m]")
    return Task(x0, radius, task.omega, task.duration, task.sign)


def run(args) -> int:
    """Design search into ``--out``: design.json and design.png."""
    from fault_tolerance.analysis.design.search import DESIGN_FILES

    with sweep_output(args.out, DESIGN_FILES):
        return _run(args)


def _run(args) -> int:
    from fault_tolerance.analysis.design.planar import VARY
    from fault_tolerance.analysis.design.search import design

    if args.vary in ("dh", "dh,limits"):
        return run_dh(args)
    if args.vary not in VARY:
        raise InvalidInput(f"--vary '{args.vary}' is not one of {[*VARY, 'dh', 'dh,limits']}")
    dh_only = [o for o, v in DH_ONLY.items() if getattr(args, v) is not None]
    dh_only += ["--deg"] if args.deg else []  # a planar design takes no angle (docs/units.md)
    if dh_only:
        raise InvalidInput(f"{', '.join(dh_only)}: options of --vary dh, not of --vary {args.vary}")
    args.objective = args.objective or "ftw-area"

    if args.task not in (None, "circle", "planar"):  # design's --task names the task path
        raise InvalidInput(
            f"--task '{args.task}' is not one of ['circle'] (design's task is the circle path; "
            "the robot's task rows are planar)"
        )
    args.task = "planar"
    arm = load_robot(args)
    arm.default_lockable = singletons(lockable_of(args, arm))
    d = design(
        arm,
        args.vary,
        args.objective,
        task=_task(args, arm),
        rcn_max=args.rcn_max,
        candidates=128 if args.candidates is None else args.candidates,
        rounds=args.rounds,
        generations=0 if args.generations is None else args.generations,
        grid=201 if args.grid is None else args.grid,
        seed=args.seed,
        workers=args.workers or 0,
        scheduler=args.scheduler,
        folder=args.out,
        progress=not args.no_progress,
    )
    from fault_tolerance.figures.design import plot_design

    d.save(args.out, draw=plot_design)
    r = d.record

    def num(v):
        return "n/a" if v is None else f"{v:.4g}"

    links = f", links [m] {np.round(r['links'], 4).tolist()}" if "links" in r else ""
    print(
        f"{arm.name}: {r['objective']} design, limits [rad] {np.round(r['limits'], 3).tolist()}"
        f"{links}; FTW area {r['area_ftw']:.4g} m², mean JVJ {num(r['jvj'])}, mean K "
        f"{num(r['rcn'])} ({r['evaluations']} designs, {r['elapsed_s']} s) -> {args.out}/design.json"
    )
    return 0
