"""Benchmark of the batched API: time per configuration against a loop over the plain API.

The case: the Panda, position task, five lockable joints, 20 000 configurations.
Both sides compute the Jacobian (Pinocchio), JVJA's rates, their jump (9)/(10) and the reduced
condition numbers (15) of every configuration; the loop is timed on a subset (``reference``
configurations) and scaled per configuration. Used by ``fault-tolerance bench``.
"""

from __future__ import annotations

import time

import numpy as np

from fault_tolerance.analysis import batch

#: The target: at least this many times less time per configuration than the loop.
TARGET_SPEEDUP = 10.0
LOCKABLE = [0, 1, 2, 3, 4]


def _workload(arm, rng, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Random configurations within the limits whose five scenarios are all tolerable."""
    Q = np.array([arm.random_q(rng) for _ in range(size)])
    xd = rng.normal(size=(size, arm.m))
    Js = batch.jacobians(arm, Q)
    ok = np.isfinite(batch.resolve("jvja", Js, xd, LOCKABLE, intolerable="nan")).all(axis=1)
    return Q[ok], xd[ok]


def bench_batch(configurations: int = 20000, reference: int = 2000, seed: int = 0) -> dict:
    """Per-configuration times [µs] of the loop and of the batched API, and their ratio."""
    from fault_tolerance.model.loading import load_arm
    from fault_tolerance.resolution.api import jvj, resolve
    from fault_tolerance.resolution.indices import rcn

    arm = load_arm("panda", task="position")
    Q, xd = _workload(arm, np.random.default_rng(seed), configurations)
    t = time.perf_counter()
    Js = batch.jacobians(arm, Q)
    qd = batch.resolve("jvja", Js, xd, LOCKABLE)
    batch.jvj(Js, xd, qd, LOCKABLE)
    batch.rcn(Js, LOCKABLE)
    t_batch = (time.perf_counter() - t) / len(Q)
    n = min(reference, len(Q))
    t = time.perf_counter()
    for q, x in zip(Q[:n], xd[:n], strict=True):
        J = arm.jacobian(q)
        v = resolve("jvja", J, x, LOCKABLE)
        jvj(J, x, v, LOCKABLE)
        rcn(J, LOCKABLE)
    t_loop = (time.perf_counter() - t) / n
    return {
        "arm": "panda (position, 5 lockable)",
        "configurations": int(len(Q)),
        "loop_us": t_loop * 1e6,
        "batch_us": t_batch * 1e6,
        "speedup": t_loop / t_batch,
        "target_speedup": TARGET_SPEEDUP,
        "passed": bool(t_loop / t_batch >= TARGET_SPEEDUP),
    }


def target_item(result: dict) -> dict:
    """The bench target row of :func:`bench_batch` (same fields as ``bench.targets``)."""
    return {
        "arm": "panda_position",
        "name": "batch_over_loop",
        "label": "loop / batched API per configuration",
        "value": result["speedup"],
        "limit": TARGET_SPEEDUP,
        "relation": ">=",
        "pass": result["passed"],
    }
