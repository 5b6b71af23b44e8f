"""``fault-tolerance bench --plan``: wall time and memory of the whole-path planner.

One planning call (:func:`fault_tolerance.planning.wholepath.plan.plan_path`) per case, timed with
``time.perf_counter``; memory is the peak of Python allocations during a second, traced call
(``tracemalloc``; slower, so not timed) and the process's maximum resident size. Targets: planar 3R
and spatial 4R 1 s paths (1000 steps) within 10 s and 20 s, a Panda pose path (r = 1) within 60 s,
a Panda position path (r = 4) within 120 s.
"""

from __future__ import annotations

import resource
import time
import tracemalloc

import numpy as np

#: case -> (robot, task, target [s]); starts and paths as in tests/test_wholepath.py.
PLAN_CASES = {
    "planar_3r_fig2": ("planar_3r", None, 10.0),
    "spatial_4r_fig7": ("spatial_4r", None, 20.0),
    "panda_pose": ("panda", "pose", 60.0),
    "panda_position": ("panda", "position", 120.0),
}
PANDA_Q0 = np.array([0.0, -0.4, 0.0, -2.0, 0.0, 1.8, 0.8])


def _problem(key: str):
    from fault_tolerance.model.loading import load_arm
    from fault_tolerance.paper.cases import CASES
    from fault_tolerance.planning.posture import initial_posture
    from fault_tolerance.simulation.paths import CirclePath

    robot, task, _ = PLAN_CASES[key]
    arm = load_arm(robot, task=task)
    if robot == "panda":
        return arm, CirclePath(arm.fk(PANDA_Q0), 0.05, 2 * np.pi, 1.0, rows=(0, 1)), PANDA_Q0, None
    case = CASES["fig2" if robot == "planar_3r" else "fig7"]
    lock = list(case.lockable)
    return arm, case.path(), initial_posture(arm, np.array(case.x0), lock).q, lock


def bench_plan(key: str, memory: bool = True) -> dict:
    """Seconds, method, objective and memory of one planning call."""
    from fault_tolerance.planning.wholepath.plan import plan_path

    arm, path, q0, lock = _problem(key)
    t0 = time.perf_counter()
    plan = plan_path(arm, path, q0=q0, lockable=lock)
    seconds = time.perf_counter() - t0
    peak = None
    if memory:
        tracemalloc.start()
        plan_path(arm, path, q0=q0, lockable=lock)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    target = PLAN_CASES[key][2]
    return {
        "case": key,
        "n": arm.n,
        "r": arm.redundancy,
        "steps": plan.info["steps"],
        "seconds": seconds,
        "target_s": target,
        "pass": seconds <= target,
        "method": plan.method,
        "scores": plan.scores,
        "improvement": plan.improvement,
        "peak_python_mib": peak,
        "max_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def format_plan_table(rows: list[dict]) -> str:
    """One line per case."""
    head = (
        f"{'case':16} {'n':>2} {'r':>2} {'steps':>6} {'seconds':>8} {'target':>7} {'':4} "
        f"{'method':20} {'mean λ':>9} {'best local':>10} {'peak MiB':>8}"
    )
    lines = [head]
    for r in rows:
        best = min(r["scores"]["lnva"], r["scores"]["jvja"])
        peak = "-" if r["peak_python_mib"] is None else f"{r['peak_python_mib']:.0f}"
        lines.append(
            f"{r['case']:16} {r['n']:2d} {r['r']:2d} {r['steps']:6d} {r['seconds']:8.2f} "
            f"{r['target_s']:7.0f} {'PASS' if r['pass'] else 'FAIL':4} {r['method']:20} "
            f"{r['scores']['final']:9.4g} {best:10.4g} {peak:>8}" + _fail_note(r)
        )
    return "\n".join(lines)


def _fail_note(r: dict) -> str:
    """A FAIL line's load average, and the first of its two measurements."""
    if r["pass"]:
        return ""
    first = f"  measured twice, first {r['first_seconds']:.2f} s" if "first_seconds" in r else ""
    load_ = r.get("loadavg")
    return first + (f"  load average {load_[0]:.2f}" if load_ else "  load average unknown")
