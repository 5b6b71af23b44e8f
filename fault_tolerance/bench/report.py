"""The benchmark's outputs: tables, target lines, the JSON file and the comparison of two files."""

from __future__ import annotations

import json
from pathlib import Path

from fault_tolerance.errors import InvalidInput
from fault_tolerance.storage.atomic import write_atomic

SCHEMA = "fault_tolerance.bench/1"


def format_table(results: dict) -> str:
    """Rows: arm, operation, median and p99 in microseconds, and the ratio to the JVJA step."""
    lines = [f"{'arm':<16}{'operation':<16}{'median µs':>11}{'p99 µs':>11}{'/ jvja':>9}"]
    for key, res in results.items():
        ops = res["ops"]
        jv = ops.get("jvja", {}).get("median_us")
        for name, st in ops.items():
            ratio = f"{st['median_us'] / jv:8.2f}x" if jv else ""
            lines.append(
                f"{key:<16}{name:<16}{st['median_us']:>11.2f}{st['p99_us']:>11.2f}{ratio:>9}"
            )
    return "\n".join(lines)


def format_targets(items: list[dict]) -> str:
    """One line per target: PASS / FAIL (or ``info``), the arm, what, the value and the limit."""
    lines = []
    for t in items:
        verdict = {True: "PASS", False: "FAIL", None: "info"}[t["pass"]]
        limit = f"(target {t['relation']} {t['limit']:g})" if t["limit"] is not None else ""
        if t["pass"] is None and t["limit"] is not None:
            limit = f"(target {t['relation']} {t['limit']:g} applies to the default backend"
            limit += " and the Panda arms)" if t["name"] == "explicit_over_jvja" else ")"
        line = f"{verdict:<5} {t['arm']:<16}{t['label']:<38}{t['value']:9.2f}  {limit}"
        lines.append(line + _remeasure_note(t))
    return "\n".join(lines)


def _remeasure_note(t: dict) -> str:
    """What a FAIL line adds: the load average beside it, and the first measurement's value."""
    note = ""
    if t.get("remeasured") and t.get("first_value") is not None:
        note = f"  measured twice, first {t['first_value']:.2f}"
    if t["pass"] is False:
        load_ = t.get("loadavg")
        note += f"  load average {load_[0]:.2f}" if load_ else "  load average unknown"
    return note


def write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` to ``path`` atomically (a temporary file in the same folder, then replace)."""
    write_atomic(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def load(path: str) -> dict:
    """A benchmark file written by ``--json``, or :class:`InvalidInput` saying why not."""
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise InvalidInput(f"{path}: cannot read it ({err.strerror})") from err
    except json.JSONDecodeError as err:
        raise InvalidInput(f"{path}: not JSON ({err.msg} at line {err.lineno})") from err
    if not isinstance(data, dict) or data.get("schema") != SCHEMA or "results" not in data:
        raise InvalidInput(f"{path}: not a benchmark file of schema {SCHEMA}")
    return data


def compare(a: dict, b: dict) -> list[dict]:
    """Per (arm, operation) in both: medians and p99 of A and B, and the ratios B / A."""
    rows = []
    for key, res_a in a["results"].items():
        res_b = b["results"].get(key)
        if res_b is None:
            continue
        for name, st_a in res_a["ops"].items():
            st_b = res_b["ops"].get(name)
            if st_b is None:
                continue
            rows.append(
                {
                    "arm": key,
                    "operation": name,
                    "median_a": st_a["median_us"],
                    "median_b": st_b["median_us"],
                    "median_ratio": st_b["median_us"] / st_a["median_us"],
                    "p99_a": st_a["p99_us"],
                    "p99_b": st_b["p99_us"],
                    "p99_ratio": st_b["p99_us"] / st_a["p99_us"],
                }
            )
    return rows


def format_compare(rows: list[dict], a_name: str, b_name: str) -> str:
    """The comparison as a table; ratio < 1 means B is faster."""
    lines = [
        f"A = {a_name}\nB = {b_name}   (ratio B/A; below 1 means B is faster)",
        f"{'arm':<16}{'operation':<16}{'A med µs':>10}{'B med µs':>10}{'B/A':>8}"
        f"{'A p99':>10}{'B p99':>10}{'B/A':>8}",
    ]
    for r in rows:
        lines.append(
            f"{r['arm']:<16}{r['operation']:<16}{r['median_a']:>10.2f}{r['median_b']:>10.2f}"
            f"{r['median_ratio']:>8.2f}{r['p99_a']:>10.2f}{r['p99_b']:>10.2f}{r['p99_ratio']:>8.2f}"
        )
    if len(lines) == 2:
        lines.append("(no arm and operation in common)")
    return "\n".join(lines)
