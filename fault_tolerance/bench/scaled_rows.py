"""Benchmark rows of the bounded step when the task is out of reach in the rate box (``s < 1``).

* ``jvja_bounded_scaled``, ``lnva_bounded_scaled``: ``Controller(limits=True)`` JVJA and LNVA
  steps on configurations of the pool with ``ẋ`` grown until the task is scaled (L3) and most
  joints are held at a bound (issue "Exact and honest under limits", item 5: long chains). Their
  targets compare them to the unbounded steps (``jvja``, ``lnva``) of the same arm.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

DESCRIPTIONS = {
    "jvja_bounded_scaled": "JVJA step with joint limits on, task scaled (s < 1, most joints at a "
    "bound)",
    "lnva_bounded_scaled": "LNVA step with joint limits on, task scaled (s < 1, most joints at a "
    "bound)",
}

#: Configurations of the pool used (the scaled bounded step of a long chain takes milliseconds).
POOL = 4
#: Growth of ``ẋ`` tried until the task is scaled with at least half of the joints at a bound.
GAINS = (1.0, 3.0, 10.0, 30.0, 100.0)


def _scaled_pool(case, ctrl) -> list[tuple]:
    """``(q, ẋ, out)`` where the bounded LNVA step scales the task with half the joints held."""
    pool = []
    for q, xd in case.qx:
        for gain in GAINS:
            ctrl.lnva(q, xd * gain)
            if ctrl.last_scale < 1.0 and 2 * int(ctrl.last_active.sum()) >= case.arm.n:
                pool.append((q, xd * gain, case.out))
                break
        if len(pool) == POOL:
            break
    return pool


def scaled_rows(case) -> dict[str, tuple[Callable[..., np.ndarray], list[tuple]]]:
    """The rows above (none when no configuration of the pool scales the task)."""
    from fault_tolerance.control.controller import Controller

    ctrl = Controller(case.arm, case.spec["lockable"], backend=case.ctrl.backend)
    pool = _scaled_pool(case, ctrl)
    if not pool:
        return {}
    return {"jvja_bounded_scaled": (ctrl.jvja, pool), "lnva_bounded_scaled": (ctrl.lnva, pool)}


__all__ = ["DESCRIPTIONS", "scaled_rows"]
