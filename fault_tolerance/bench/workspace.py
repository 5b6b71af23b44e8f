"""Benchmark of the workspace sweep: one Dask worker against two.

``fault-tolerance bench --workspace [GRID]`` runs the same command (:func:`command`) as separate
processes: a 201 x 201 planar-3R map on one worker (target: under 30 s), then a GRID x GRID map
(default 801) on one worker and on two. It reports the wall time and the CPU time (user + system
of the process and its worker processes) of each run, the ratio of the wall times (target: two
workers at least 1.7x faster) and whether the two maps are identical. The machine's load average
is recorded before and after: a machine shared with other work slows the two-worker run most (it
needs both cores), so compare the CPU totals, which should be about equal.

Example:
    >>> from fault_tolerance.bench.workspace import command
    >>> command(401, 2, "out")[3:7]
    ['workspace', '--robot', 'planar_3r', '--limits=-60:60,-120:120,-120:120']
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fault_tolerance.errors import FaultToleranceError

#: The targets: two workers at least this many times faster than one on a large map ...
TARGET_SPEEDUP = 1.7
#: ... and a 201 x 201 planar-3R map within this many seconds on one worker.
MAX_SMALL_S = 30.0
GRID = 801
SMALL_GRID = 201
CHUNKS = 32
LIMITS = "-60:60,-120:120,-120:120"


def command(grid: int, workers: int, out: str | Path) -> list[str]:
    """The timed command: the planar 3R with artificial limits [deg] on ``workers`` workers."""
    return [
        sys.executable, "-m", "fault_tolerance", "workspace", "--robot", "planar_3r",
        f"--limits={LIMITS}", "--deg", "--grid", str(grid), "--chunks", str(CHUNKS),
        "--workers", str(workers), "--no-progress", "--out", str(out),
    ]  # fmt: skip


def _timed(cmd: list[str]) -> dict:
    """Wall and CPU seconds of one run of ``cmd`` (CPU: the child and its worker processes)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
        raise FaultToleranceError(f"`{' '.join(cmd[2:])}` failed: {tail[0]}")
    return {
        "wall_s": wall,
        "user_s": after.ru_utime - before.ru_utime,
        "sys_s": after.ru_stime - before.ru_stime,
    }


def _same_maps(a: Path, b: Path) -> bool:
    """The two ``workspace.npz`` hold identical arrays (NaN where NaN)."""
    with np.load(a / "workspace.npz") as x, np.load(b / "workspace.npz") as y:
        return x.files == y.files and all(
            np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f") for k in x.files
        )


def bench_workspace(grid: int = GRID, progress=None) -> dict:
    """Time the small map on one worker and the ``grid`` map on one and two workers."""
    say = progress or (lambda msg: None)
    load_before = list(os.getloadavg())
    with tempfile.TemporaryDirectory(prefix="ft-bench-ws-") as tmp:
        say(f"workspace {SMALL_GRID}x{SMALL_GRID}, 1 worker")
        small = _timed(command(SMALL_GRID, 1, Path(tmp) / "small"))
        runs = {}
        for w in (1, 2):
            say(f"workspace {grid}x{grid}, {w} worker{'s' if w > 1 else ''}")
            runs[w] = _timed(command(grid, w, Path(tmp) / f"w{w}"))
        identical = _same_maps(Path(tmp) / "w1", Path(tmp) / "w2")
    speedup = runs[1]["wall_s"] / runs[2]["wall_s"]
    return {
        "command": "fault-tolerance " + " ".join(command(grid, 2, "OUT")[3:]),
        "grid": grid,
        "chunks": CHUNKS,
        "small": small,
        "one": runs[1],
        "two": runs[2],
        "speedup": speedup,
        "identical": identical,
        "loadavg_before": load_before,
        "loadavg_after": list(os.getloadavg()),
        "target_speedup": TARGET_SPEEDUP,
        "max_small_s": MAX_SMALL_S,
    }


def target_items(r: dict) -> list[dict]:
    """The bench target rows of :func:`bench_workspace` (same fields as ``bench.targets``)."""
    g = r["grid"]
    return [
        {"arm": "planar_3r", "name": "workspace_201_one_worker_s",
         "label": f"workspace {SMALL_GRID}² map, 1 worker [s]", "value": r["small"]["wall_s"],
         "limit": MAX_SMALL_S, "relation": "<", "pass": r["small"]["wall_s"] < MAX_SMALL_S},
        {"arm": "planar_3r", "name": "workspace_two_over_one",
         "label": f"workspace {g}² map, 1 / 2 workers", "value": r["speedup"],
         "limit": TARGET_SPEEDUP, "relation": ">=",
         "pass": bool(r["speedup"] >= TARGET_SPEEDUP and r["identical"])},
    ]  # fmt: skip


def format_workspace(r: dict) -> str:
    """The printed lines of :func:`bench_workspace`."""

    def cpu(x: dict) -> str:
        total = x["user_s"] + x["sys_s"]
        return f"{x['wall_s']:6.1f} s wall, {total:6.1f} s CPU ({x['sys_s']:.1f} s system)"

    g = r["grid"]
    return "\n".join(
        [
            f"workspace sweep: {r['command']} (and --workers 1)",
            f"  {SMALL_GRID}x{SMALL_GRID}, 1 worker : {cpu(r['small'])}",
            f"  {g}x{g}, 1 worker : {cpu(r['one'])}",
            f"  {g}x{g}, 2 workers: {cpu(r['two'])}",
            f"  two workers {r['speedup']:.2f}x faster (target >= {TARGET_SPEEDUP}), maps "
            f"{'identical' if r['identical'] else 'DIFFERENT'}; load average "
            f"{r['loadavg_before'][0]:.2f} before, {r['loadavg_after'][0]:.2f} after (the machine's "
            "other work slows the two-worker run most)",
        ]
    )
