"""The Controller's step for a resolver without a compiled kernel: its reference rates.

A resolver registered with ``compiled=None`` (:mod:`fault_tolerance.resolution.registry`), or a
built-in given options its kernel does not take, steps here: the Jacobian from the Controller's own
``pinocchio.Data`` (its :class:`~fault_tolerance.control.workspace.ControllerWorkspace`), then the
entry's ``rates`` (under joint limits its ``bounded`` variant in the rate box (L1) at ``q``). The
last step's state and the bounded-step counters go into the workspace, as the compiled steps do.
The same signature as the compiled steps, ``step(q, xdot, out=None)``; not allocation-free.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fault_tolerance.control.indices import jacobian
from fault_tolerance.control.workspace import (
    BOUNDED_REFERENCE_STEPS,
    BOUNDED_STEPS,
    ControllerWorkspace,
)
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.joint_limits import arm_rate_box
from fault_tolerance.resolution.bounded import SCALE_TOL
from fault_tolerance.resolution.registry import ResolverEntry


def generic_step(
    ws: ControllerWorkspace, entry: ResolverEntry, options: dict, horizon: float | None
) -> Callable[..., np.ndarray]:
    """``step(q, xdot, out=None) -> qd`` of ``entry`` in the Controller's workspace ``ws``.

    ``options`` are the resolver's (``entry.options_with``); ``horizon`` [s] is the rate box's
    under joint limits, ``None`` without them.
    """
    n, m, arm, sc = ws.n, ws.m, ws.arm, ws.scenarios

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        xdot = np.asarray(xdot, dtype=float)
        if q.shape != (n,) or xdot.shape != (m,):
            raise InvalidInput(
                f"q has shape {q.shape} and xdot {xdot.shape}; {arm.name} needs ({n},) and ({m},)"
            )
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(xdot))):
            raise InvalidInput("q and xdot must be finite")
        J = jacobian(ws, q)
        context = dict(tolerate=ws.tolerate, joint_names=arm.joint_names, arm=arm, q=q)
        if horizon is not None:
            lo, hi = arm_rate_box(arm, q, horizon)
            res = entry.call_bounded(J, xdot, sc, lo, hi, **context, **options)
            qd = res.qd
            met = bool(np.any(res.active)) or res.scale < 1.0 - SCALE_TOL
            state = ws.box_state
            state[0], state[1], state[2:] = res.scale, 1.0 if met else 0.0, res.active
            ws.counts[BOUNDED_STEPS] += met
            ws.counts[BOUNDED_REFERENCE_STEPS] += met
        else:
            qd = entry.call(J, xdot, sc, **context, **options)
        if out is None:
            return np.array(qd, dtype=float)
        out[...] = qd
        return out

    return step
