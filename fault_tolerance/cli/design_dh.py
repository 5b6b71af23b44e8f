"""``fault-tolerance design --vary dh``: DH parameters of a spatial arm by jump and RCN."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fault_tolerance.cli.common import add_deg_option, dh_params_from_degrees, floats
from fault_tolerance.errors import InvalidInput

#: The parameters varied by default on the paper's 4R: upper arm and forearm, total length fixed.
DEFAULT_PARAMS = {"spatial_4r": "d3:0.2:0.6,a4:0.1:0.5"}
#: Options of --vary dh alone (flag -> argparse dest); a planar design refuses them.
DH_ONLY = {"--dh": "dh", "--params": "params", "--total-length": "total_length",
           "--popsize": "popsize", "--search-dt": "search_dt", "--csv": "csv"}  # fmt: skip
#: Options of a planar design alone; --vary dh refuses them.
PLANAR_ONLY = {"--candidates": "candidates", "--grid": "grid"}
#: Default task of a template: the paper's Fig. 6 circle for the 4R.
DEFAULT_TASKS = {"spatial_4r": ((0.09, 0.21, 0.27), 0.075)}


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The options of ``--vary dh``."""
    g = s.add_argument_group("DH design (--vary dh)")
    g.add_argument(
        "--dh",
        default=None,
        help="the base arm: a DH file (.json or .csv, docs/design.md) or a template "
        "(spatial_4r | anthropomorphic_7r) (default spatial_4r)",
    )
    g.add_argument(
        "--params",
        default=None,
        help="varied parameters FIELDJOINT:LO:HI or FIELDJOINT:{A|B|..}, fields a d theta alpha "
        "lower upper, e.g. d3:0.2:0.6,a4:0.1:0.5,alpha2:{0|pi/2|-pi/2} "
        "(default for spatial_4r: d3:0.2:0.6,a4:0.1:0.5)",
    )
    g.add_argument(
        "--csv",
        default=None,
        help="the task path from a CSV file with header t,x,y,z [,vx,vy,vz] (times [s], "
        "positions [m]) instead of the circle --x0/--radius",
    )
    add_deg_option(g, "the angles of --params (theta, alpha; lower, upper of revolute joints)")
    g.add_argument(
        "--total-length",
        default=None,
        help="fixed (every length scaled so that the sum of |a|, |d| and the tool offset is the "
        "base arm's) | free | a number [m] (default fixed)",
    )
    g.add_argument(
        "--popsize", type=int, default=None, help="DE population per parameter (default 6)"
    )
    g.add_argument(
        "--generations",
        type=int,
        default=None,
        help="differential-evolution generations after the first population (default 8 for "
        "--vary dh, 0 for a planar 3R: its quasi-random first population and the pattern search)",
    )
    g.add_argument(
        "--search-dt", type=float, default=None, help="time step of the search's runs [s] (the "
        "chosen design is re-run at 1 ms) (default 0.01)",
    )  # fmt: skip


def _table(args):
    from fault_tolerance.model.dh import TEMPLATES, read_dh

    if args.dh in TEMPLATES:
        return TEMPLATES[args.dh], args.dh
    if Path(args.dh).suffix.lower() in (".json", ".csv"):
        return read_dh(args.dh), None
    raise InvalidInput(
        f"--dh {args.dh!r} is neither a DH file (.json, .csv) nor a template {sorted(TEMPLATES)}"
    )


def _task(args, template):
    from fault_tolerance.analysis.design.dh import DHTask
    from fault_tolerance.simulation.paths import load_csv

    if args.csv:
        if args.x0 is not None or args.radius is not None:
            raise InvalidInput("--csv is the whole task path: give it without --x0 and --radius")
        return DHTask.sampled(load_csv(args.csv))
    x0, radius = DEFAULT_TASKS.get(template, (None, None))
    if args.x0 is not None:
        x0 = tuple(floats(args.x0, "--x0"))
    if args.radius is not None:
        radius = args.radius
    if x0 is None or radius is None:
        raise InvalidInput("--vary dh with this arm needs the task circle: --x0 x,y,z --radius R")
    if len(x0) != 3 or not (np.isfinite(radius) and radius > 0):
        raise InvalidInput("--x0 needs three numbers x,y,z [m] and --radius a positive number [m]")
    return DHTask(x0, float(radius))


def _check_angles(params, table, deg: bool) -> None:
    """The angles of ``--params`` in range: θ, α within ±4π, revolute limits within a turn [rad].

    A value out of range that is beyond 2π gets the degrees hint when ``deg`` is off.
    """
    from fault_tolerance.model.dh import MAX_ANGLE
    from fault_tolerance.model.joint_limits import DEGREES_OPTION_HINT, TURN_LIMIT

    for p in params:
        kind = table.joints[p.joint - 1].kind if p.joint <= table.n else "prismatic"
        if p.field in ("theta", "alpha"):
            bound, what = MAX_ANGLE, "DH angles alpha, theta"
        elif p.field in ("lower", "upper") and kind == "revolute":
            bound, what = TURN_LIMIT, "revolute joint limits"
        else:
            continue
        values = p.choices or (p.lo, p.hi)
        if max(abs(v) for v in values) > bound:
            hint = "" if deg else f"; {DEGREES_OPTION_HINT}"
            raise InvalidInput(
                f"--params {p.name} {[round(v, 6) for v in values]} rad: {what} must be within "
                f"±{bound:.4g} rad{hint}"
            )


def _total(text: str, table) -> float | None:
    if text == "free":
        return None
    if text == "fixed":
        return table.length
    try:
        return float(text)
    except ValueError:
        raise InvalidInput(f"--total-length {text!r} is not fixed, free or a number [m]") from None


def run_dh(args) -> int:
    """The DH design into ``--out``: design.json, design.urdf, design.png, replay.html."""
    from fault_tolerance.analysis.design.dh import design_spec, dh_design, parse_params
    from fault_tolerance.figures.design import plot_dh_design
    from fault_tolerance.resolution.indices import RCN_THRESHOLD

    planar = [o for o, v in PLANAR_ONLY.items() if getattr(args, v) is not None]
    if planar:
        raise InvalidInput(f"{', '.join(planar)}: options of a planar design, not of --vary dh")
    args.dh = args.dh or "spatial_4r"
    args.total_length = args.total_length or "fixed"
    args.popsize = 6 if args.popsize is None else args.popsize
    args.search_dt = 1e-2 if args.search_dt is None else args.search_dt
    if args.robot or args.description:
        raise InvalidInput(
            "--vary dh takes its arm from --dh FILE|TEMPLATE, not --robot/--description"
        )
    table, template = _table(args)
    text = args.params or DEFAULT_PARAMS.get(template)
    if text is None:
        raise InvalidInput("--vary dh with a DH file needs --params (e.g. d3:0.2:0.6,a4:0.1:0.5)")
    given = len(parse_params(text))  # the user's parameters come first (--deg converts them)
    if args.vary == "dh,limits":  # every joint's limits join the varied parameters
        text += "," + ",".join(
            f"lower{i}:-3.1416:-0.5,upper{i}:0.5:3.1416" for i in range(1, table.n + 1)
        )
    params = parse_params(text)
    if args.deg:
        params = dh_params_from_degrees(params[:given], table, args.params or "") + params[given:]
    _check_angles(params, table, args.deg)
    objective = args.objective or "mean-jvj"
    lockable = _lockable(args, table)
    spec = design_spec(
        table, params, _task(args, template), lockable, objective=objective,
        rcn_max=RCN_THRESHOLD if args.rcn_max is None else args.rcn_max,
        total_length=_total(args.total_length, table), search_dt=args.search_dt,
    )  # fmt: skip
    generations = 8 if args.generations is None else args.generations
    d = dh_design(
        spec, seed=args.seed, popsize=args.popsize, generations=generations,
        pattern_rounds=args.rounds, workers=args.workers or 0, scheduler=args.scheduler,
        folder=args.out, progress=not args.no_progress,
    )  # fmt: skip
    d.save(args.out, draw=plot_dh_design, extra=lambda tmp: _replay(d, spec, tmp))
    r, b = d.record, d.record["baseline"]
    names = ", ".join(f"{k} = {v:.4g}" for k, v in r["parameters"].items())
    print(
        f"{table.name}: {objective} design {names}; mean jump {r['mean_jvj']:.4g} (rad/s)² "
        f"(baseline {_num(b['mean_jvj'])}), largest k_S {r['rcn_max']:.4g} "
        f"(limit {spec['rcn_max']:g}){_volume(r)}; {r['evaluations']} designs -> "
        f"{args.out}/design.json"
    )
    return 0


def _volume(r: dict) -> str:
    """The failure-tolerant volume part of the summary line (objective ftw-volume only)."""
    if r.get("ftw_volume") is None:
        return ""
    return (
        f", failure-tolerant volume {r['ftw_volume']:.4g} m³ "
        f"(baseline {_num(r['baseline'].get('ftw_volume'))})"
    )


def _num(v) -> str:
    return "n/a" if v is None else f"{v:.4g}"


def _lockable(args, table) -> list[str]:
    names = [f"joint{i}" for i in range(1, table.n + 1)]
    if args.lockable in (None, "all"):
        return names[:3] if table.n == 4 and args.dh == "spatial_4r" else names
    chosen = [s.strip() for s in args.lockable.split(",") if s.strip()]
    bad = [j for j in chosen if j not in names]
    if bad:
        raise InvalidInput(f"--lockable {bad}: the DH arm's joints are {names}")
    return chosen


def _replay(d, spec, out: Path) -> None:
    """A replay page of the chosen arm on the task, from the design's start (replay.html)."""
    from fault_tolerance.analysis.design.dh import DHTask
    from fault_tolerance.model.dh import arm_from_dh
    from fault_tolerance.simulation.simulate import simulate
    from fault_tolerance.viz.page import export_html

    arm = arm_from_dh(d.table, task="position")
    path = DHTask.from_spec(spec["task"]).path()
    run = simulate(arm, path, "jvja", q0=np.array(d.record["q0"]), lockable=spec["lockable"],
                   limits=False)  # fmt: skip
    export_html(run, out / "replay.html", arm)
