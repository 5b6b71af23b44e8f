"""Markdown tables of a saved ``fault-tolerance bench --json FILE`` run, for the README.

Every bench number the README quotes is pasted from this script's output, so it can be traced to
one saved run (the command, the machine and its load are printed above the tables)::

    fault-tolerance bench --json bench.json
    python scripts/bench_tables.py bench.json            # every row
    python scripts/bench_tables.py bench.json --ops jacobian,floor,lnva,jvja,sim_jvja
    python scripts/bench_tables.py chains.json --ratios      # the scaling table
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def header(bench: dict) -> str:
    """One line naming the command, the machine and its load while it ran."""
    m = bench.get("machine", {})
    load = ", ".join(f"{v:.1f}" for v in m.get("loadavg", []))
    return (
        f"`{Path(bench['command'].split()[0]).name} {' '.join(bench['command'].split()[1:])}`, "
        f"{bench.get('created', '?')}, {m.get('cpu', '?')} x {m.get('cores', '?')} cores, "
        f"load average {load}"
    )


def ops_table(bench: dict, ops: list[str] | None) -> str:
    """Rows: operations; columns: arms; cells: median / p99 in µs."""
    arms = list(bench["results"])
    names = ops or list(dict.fromkeys(k for a in arms for k in bench["results"][a]["ops"]))
    lines = [
        "| operation (median / p99 µs) | " + " | ".join(arms) + " |",
        "|---|" + "---|" * len(arms),
    ]
    for op in names:
        cells = []
        for a in arms:
            row = bench["results"][a]["ops"].get(op)
            cells.append("" if row is None else f"{row['median_us']:.2f} / {row['p99_us']:.2f}")
        lines.append(f"| {op} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def targets_table(bench: dict) -> str:
    """Every target with its value, limit and verdict."""
    lines = ["| arm | target | value | limit | verdict |", "|---|---|---|---|---|"]
    for t in bench.get("targets", []):
        if t.get("limit") is None:
            continue
        verdict = {True: "PASS", False: "FAIL", None: "info (target not applied here)"}[t["pass"]]
        lines.append(
            f"| {t['arm']} | {t['label']} | {t['value']:.3g} | {t['relation']} {t['limit']:g} "
            f"| {verdict} |"
        )
    return "\n".join(lines)


def ratio_table(bench: dict) -> str:
    """Rows: arms (the chains of the scaling table); medians in µs and the ratios."""
    lines = [
        "| arm | Jacobian | floor | LNVA | JVJA | JVJA / LNVA | JVJA / floor | two-joint JVJA "
        "| simulated JVJA sample | the same under limits (÷ bounded step, no bound) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for arm, res in bench["results"].items():
        med = {k: v["median_us"] for k, v in res["ops"].items()}

        def cell(op, over=None, med=med):
            if op not in med:
                return "(none)"
            if over is None:
                return f"{med[op]:.2f}"
            return f"{med[op]:.2f} ({med[op] / med[over]:.2f}×)"

        jv = med.get("jvja")
        lines.append(
            f"| {arm} | {cell('jacobian')} | {cell('floor')} | {cell('lnva')} | {cell('jvja')} "
            f"| {jv / med['lnva']:.2f} | {jv / med['floor']:.2f} | {cell('jvja_multi', 'jvja')} "
            f"| {cell('sim_jvja', 'jvja')} | {cell('sim_jvja_lim', 'jvja_bounded_free')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the header, the operations table and the targets table of one saved run."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("json", help="a file written by fault-tolerance bench --json FILE")
    p.add_argument("--ops", default=None, help="comma-separated operations (default: all)")
    p.add_argument(
        "--ratios",
        action="store_true",
        help="print the per-arm ratio table (the README's scaling table) instead",
    )
    args = p.parse_args(argv)
    try:
        bench = json.loads(Path(args.json).read_text())
        if not str(bench.get("schema", "")).startswith("fault_tolerance.bench/"):
            raise ValueError("not a fault-tolerance bench file (schema missing)")
    except (OSError, ValueError) as err:
        print(f"bench_tables: error: {args.json}: {err}", file=sys.stderr)
        return 2
    if args.ratios:
        print(header(bench) + "\n\n" + ratio_table(bench))
        return 0
    ops = [o for o in (args.ops or "").split(",") if o] or None
    print(header(bench) + "\n\n" + ops_table(bench, ops) + "\n\n" + targets_table(bench))
    return 0


if __name__ == "__main__":
    sys.exit(main())
