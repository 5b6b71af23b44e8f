"""How the benchmark times a call: blocks of consecutive calls taking turns, GC off; statistics."""

from __future__ import annotations

import gc
import time
from collections.abc import Callable

import numpy as np

#: Rounds of blocks per row (see :func:`time_rows`) and untimed calls at the start of a block.
ROUNDS = 10
BLOCK_WARMUP = 3

#: A benchmark row: the function and the argument tuples it is called with in turn.
Row = tuple[Callable, list[tuple]]


def time_rows(
    rows: dict[str, Row], steps: int, warmup: int, rounds: int = ROUNDS
) -> dict[str, np.ndarray]:
    """Time single calls of each row; nanoseconds, shape (steps,).

    The calls of a row are timed in blocks of consecutive calls (the steady state of a control
    loop: one call after another, caches warm for that row), and the rows' blocks take turns over
    ``rounds`` rounds, so a drift of the machine hits every row alike. The first
    :data:`BLOCK_WARMUP` calls of each block are not timed (switching rows refills caches).
    """
    pc = time.perf_counter_ns
    items = [(name, fn, args) for name, (fn, args) in rows.items()]
    out = {name: np.empty(steps) for name in rows}
    for _, fn, args in items:
        for i in range(warmup):
            fn(*args[i % len(args)])
    rounds = max(1, min(rounds, steps))
    bounds = np.linspace(0, steps, rounds + 1).astype(int)
    gc.collect()
    enabled = gc.isenabled()
    gc.disable()
    try:
        for r in range(rounds):
            lo, hi = int(bounds[r]), int(bounds[r + 1])
            for name, fn, args in items:
                samples, k = out[name], len(args)
                for i in range(BLOCK_WARMUP):
                    fn(*args[(lo + i) % k])
                for i in range(lo, hi):
                    a = args[i % k]
                    t0 = pc()
                    fn(*a)
                    t1 = pc()
                    samples[i] = t1 - t0
    finally:
        if enabled:
            gc.enable()
    return out


def timer_overhead_ns(n: int = 20000) -> float:
    """Median cost of one pair of timer reads [ns]."""
    pc = time.perf_counter_ns
    d = np.empty(n)
    for i in range(n):
        t0 = pc()
        t1 = pc()
        d[i] = t1 - t0
    return float(np.median(d))


def stats(ns: np.ndarray) -> dict:
    """Median, p99, mean, min, max [µs] and count of call times given in ns."""
    us = ns / 1e3
    return {
        "median_us": float(np.median(us)),
        "p99_us": float(np.percentile(us, 99)),
        "mean_us": float(us.mean()),
        "min_us": float(us.min()),
        "max_us": float(us.max()),
        "steps": int(len(us)),
    }
