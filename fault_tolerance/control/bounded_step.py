"""The bounded step of :class:`~fault_tolerance.control.controller.Controller`: fast step, box check, then QP.

A bounded step takes the controller's unbounded fast step, builds the rate box (L1) at ``q`` in
preallocated buffers and checks the rates (for JVJA also every reduced robot's rates (G1), the
target of its bounded objective (L2)) against it (:mod:`fault_tolerance.control.fast.box_check`, re-exported
here). Only when a bound is met does it solve the bounded problem. With the numba backend all of
it is one compiled call (:mod:`fault_tolerance.control.fast.bounded_step`); the reference route here (the fast step,
the check, :func:`fault_tolerance.resolution.bounded.resolve_bounded`) serves the other backends and every step
the compiled solve refuses. See docs/MATH.md "Joint limits" and "Joint limits, compiled".
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import numpy as np

from fault_tolerance.control.fast.box_check import box_status_numpy, compiled_box_status
from fault_tolerance.control.indices import jacobian, jacobian_derivatives
from fault_tolerance.control.workspace import (
    BOUNDED_REFERENCE_STEPS,
    BOUNDED_STEPS,
    FALLBACKS,
    ControllerWorkspace,
)
from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.joint_limits import NO_LIMIT, velocity_limits
from fault_tolerance.resolution.bounded import resolve_bounded
from fault_tolerance.resolution.registry import KERNEL_JVJA, KERNEL_MDA, get


def bounded_step(
    cw: ControllerWorkspace, name: str, inner: Callable, horizon: float, backend: str
) -> Callable:
    """``step(q, xdot, out=None)``: ``inner`` (the unbounded fast step), inside the rate box.

    ``cw`` is the workspace of the :class:`~fault_tolerance.control.controller.Controller` being
    built, ``backend`` its backend. With the numba backend, LNVA and single-joint JVJA take the whole
    step after the Jacobian in one compiled call
    (:func:`fault_tolerance.control.fast.bounded_solve.free_then_bounded`); MDA (the paper's
    baseline), multi-joint JVJA, the other backends and every step the compiled solve refuses take
    the reference route: ``inner``, the box check, and
    :func:`~fault_tolerance.resolution.bounded.resolve_bounded` only when a bound is met.

    Writes ``cw.box_state`` (task scaling of the last step, 1 when ``ẋ`` was reached; the joints
    held at a bound: the Controller's ``last_scale``, ``last_active``); counts the steps that
    needed the bounded solver and those solved by the reference in ``cw.counts``.
    """
    if not (np.isfinite(horizon) and horizon > 0):
        raise InvalidInput(f"horizon must be finite and > 0 [s], got {horizon}")
    arm, n = cw.arm, cw.n
    lim = np.empty((3, n))
    lim[0] = np.where(np.abs(arm.lower) < NO_LIMIT, arm.lower, -np.inf)
    lim[1] = np.where(np.abs(arm.upper) < NO_LIMIT, arm.upper, np.inf)
    lim[2] = velocity_limits(arm)
    prm = np.array([1.0 / horizon, cw.alpha])
    reference = _reference_step(cw, name, inner, lim, prm, backend)
    if backend != "numba":
        return reference
    from fault_tolerance.control.fast.bounded_step import compiled_bounded_step, covers

    if not covers(cw, name):  # MDA and multi-joint JVJA: the reference route (compiled box check)
        return reference
    return compiled_bounded_step(cw, name, reference, lim, prm)


def _reference_step(
    cw: ControllerWorkspace, name: str, inner: Callable, lim, prm, backend: str
) -> Callable:
    """The reference route: ``inner``, the box check, :func:`resolve_bounded` when a bound is met."""
    n, counts, state = cw.n, cw.counts, cw.box_state
    buf = np.empty((4, n))  # lo, hi, scratch (n), scratch (m <= n)
    lo, hi = buf[0], buf[1]
    ws = cw.jvja_factors  # [P, Q, c] of the last JVJA fast step, N = I - PᵀQ (set by the kernels)
    mode = get(name).compiled  # the built-in kernel this step checks
    jv = mode == KERNEL_JVJA and cw.singletons
    cols = cw.scenarios.columns if cw.singletons else np.zeros(0, dtype=np.int64)
    check = compiled_box_status() if backend == "numba" else box_status_numpy
    dummy = np.zeros((cw.m, n)), np.zeros((cw.m, n)), np.zeros(n)
    sc = cw.scenarios
    general = mode == KERNEL_JVJA and not cw.singletons

    def slow(q, xdot, out):
        J = jacobian(cw, q)
        opts = {"tolerate": cw.tolerate}
        if mode == KERNEL_MDA:
            opts.update(dJ=jacobian_derivatives(cw, q), gain=cw.gain, max_step=cw.max_step)
        box_status_numpy(q, lim, prm, buf, out, *dummy, cols, False)  # the box (L1) at q
        box = (lo.copy(), hi.copy())
        res = resolve_bounded(name, J, np.asarray(xdot, dtype=float), sc, bounds=box, **opts)
        out[...] = res.qd
        state[0], state[1], state[2:] = res.scale, 1.0, res.active  # the compiled steps' state too
        counts[BOUNDED_STEPS] += 1
        counts[BOUNDED_REFERENCE_STEPS] += 1
        return out

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        before = counts[FALLBACKS]
        out = inner(q, xdot, out)
        fresh = jv and counts[FALLBACKS] == before
        P, Q, c = (ws[0], ws[1], ws[2]) if fresh else dummy
        status = check(q, lim, prm, buf, out, P, Q, c, cols, fresh)
        if status or general or (jv and not fresh):
            return slow(q, xdot, out)
        state[0], state[1] = 1.0, 0.0
        state[2:] = 0.0
        return out

    def finish(q, xdot, out):
        """The box check and, when a bound is met, :func:`resolve_bounded`, for given rates."""
        if box_status_numpy(q, lim, prm, buf, out, *dummy, cols, False):
            return slow(q, xdot, out)
        state[0], state[1] = 1.0, 0.0
        state[2:] = 0.0
        return out

    carrier = cast(Any, step)  # a function that carries its two helpers as attributes
    carrier.slow, carrier.finish = slow, finish
    step.__name__ = name
    step.__doc__ = f"{name} inside the rate box of the joint limits (reference route)."
    return step


__all__ = [
    "bounded_step",
]
