"""The Controller's step for a resolver without a compiled kernel: its reference rates.

A resolver registered with ``compiled=None`` (:mod:`fault_tolerance.resolution.registry`), or a
built-in given options its kernel does not take, steps here: the Jacobian from the Controller's own
``pinocchio.Data``, then the entry's ``rates`` (under joint limits its ``bounded`` variant in the
rate box (L1) at ``q``). The same signature as the compiled steps, ``step(q, xdot, out=None)``; not
allocation-free.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.joint_limits import arm_rate_box
from fault_tolerance.resolution.bounded import SCALE_TOL
from fault_tolerance.resolution.registry import ResolverEntry


def generic_step(ctrl, entry: ResolverEntry, options: dict) -> Callable[..., np.ndarray]:
    """``step(q, xdot, out=None) -> qd`` of ``entry`` for the Controller ``ctrl``."""
    n, m, arm, sc = ctrl.n, ctrl.m, ctrl.arm, ctrl.scenarios

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        xdot = np.asarray(xdot, dtype=float)
        if q.shape != (n,) or xdot.shape != (m,):
            raise InvalidInput(
                f"q has shape {q.shape} and xdot {xdot.shape}; {arm.name} needs ({n},) and ({m},)"
            )
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(xdot))):
            raise InvalidInput("q and xdot must be finite")
        J = ctrl.jacobian(q)
        context = dict(tolerate=ctrl.tolerate, joint_names=arm.joint_names, arm=arm, q=q)
        if ctrl.limits:
            lo, hi = arm_rate_box(arm, q, ctrl.horizon)
            res = entry.call_bounded(J, xdot, sc, lo, hi, **context, **options)
            qd = res.qd
            met = bool(np.any(res.active)) or res.scale < 1.0 - SCALE_TOL
            state = ctrl._box_state
            state[0], state[1], state[2:] = res.scale, 1.0 if met else 0.0, res.active
            ctrl.bounded_steps += met
            ctrl.bounded_reference_steps += met
        else:
            qd = entry.call(J, xdot, sc, **context, **options)
        if out is None:
            return np.array(qd, dtype=float)
        out[...] = qd
        return out

    return step
