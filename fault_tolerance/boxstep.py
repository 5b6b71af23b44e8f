"""The bounded step of :class:`~fault_tolerance.realtime.Controller`: fast step, box check, then QP.

A bounded step takes the controller's unbounded fast step, builds the rate box (L1) at ``q`` in
preallocated buffers and checks the rates (for JVJA also every reduced robot's rates (G1), the
target of its bounded objective (L2)) against it: one pass over ``n²`` numbers, compiled by numba
with the numba backend. Only when a bound is met does it solve the bounded problem
(:func:`fault_tolerance.bounded.resolve_bounded`). See docs/MATH.md "Joint limits".
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .boxqp import BOX_TOL
from .bounded import NO_LIMIT, RATE_HORIZON, resolve_bounded
from .errors import InvalidInput
from .limits import velocity_limits


def box_status(q, lim, prm, buf, out, P, Q, c, cols, jv):  # pragma: no cover - numba
    """Box (L1) at ``q`` into ``buf[0], buf[1]``; 0 when ``out`` (and, ``jv``, each (G1) rate) is inside.

    ``lim`` rows: lower, upper position limits, velocity limits; ``prm = [1/h, alpha]``; ``out =
    a + alpha N c`` is the JVJA step (``c`` its pivot ratios) with ``N = I - PᵀQ`` (the kernels
    never form N: ``P = Q = Y = L⁻¹J`` compiled, ``P = J, Q = G⁻¹J`` with LAPACK), so ``N[:, i] =
    e_i - Pᵀ Q[:, i]``; ``buf[2]`` (n) and ``buf[3, :m]`` are scratch. Plain Python with scalar
    loops (compiled by numba with the numba backend). Returns 1 when ``out`` leaves the box, 2 when
    a reduced robot's rates do.
    """
    n = q.shape[0]
    m = P.shape[0]
    lower, upper, vmax = lim[0], lim[1], lim[2]
    lo, hi, a, y = buf[0], buf[1], buf[2], buf[3]
    ih, alpha = prm[0], prm[1]
    bad = 0
    for j in range(n):
        lj = (lower[j] - q[j]) * ih
        hj = (upper[j] - q[j]) * ih
        v = vmax[j]
        lj = -v if lj < -v else (v if lj > v else lj)
        hj = -v if hj < -v else (v if hj > v else hj)
        lo[j] = lj
        hi[j] = hj
        if out[j] < lj - BOX_TOL or out[j] > hj + BOX_TOL:
            bad = 1
    if bad or not jv:
        return bad
    for r in range(m):  # N c = c - Pᵀ (Q c), N never formed
        s = 0.0
        for k in range(n):
            s += Q[r, k] * c[k]
        y[r] = s
    for j in range(n):
        s = c[j]
        for r in range(m):
            s -= P[r, j] * y[r]
        a[j] = out[j] - alpha * s
    for t in range(cols.shape[0]):
        i = cols[t]
        nii = 1.0
        for r in range(m):
            nii -= P[r, i] * Q[r, i]
        ratio = a[i] / nii
        for j in range(n):
            if j == i:
                continue
            nji = 0.0  # N[j, i] = -P_jᵀ Q_i off the diagonal
            for r in range(m):
                nji -= P[r, j] * Q[r, i]
            p = a[j] - ratio * nji
            if p < lo[j] - BOX_TOL or p > hi[j] + BOX_TOL:
                return 2
    return 0


def box_status_numpy(q, lim, prm, buf, out, P, Q, c, cols, jv):
    """:func:`box_status` with NumPy array operations (the lapack and numpy backends)."""
    lower, upper, vmax = lim[0], lim[1], lim[2]
    lo, hi, a = buf[0], buf[1], buf[2]
    ih, alpha = prm[0], prm[1]
    np.subtract(lower, q, out=lo)
    np.multiply(lo, ih, out=lo)
    np.clip(lo, -vmax, vmax, out=lo)
    np.subtract(upper, q, out=hi)
    np.multiply(hi, ih, out=hi)
    np.clip(hi, -vmax, vmax, out=hi)
    if (out < lo - BOX_TOL).any() or (out > hi + BOX_TOL).any():
        return 1
    if not jv:
        return 0
    np.subtract(c, P.T @ (Q @ c), out=a)  # N c = c - Pᵀ (Q c)
    np.multiply(a, -alpha, out=a)
    np.add(a, out, out=a)
    k = np.arange(len(cols))
    Ncols = -(P.T @ Q[:, cols]).T  # row t: N[cols[t], :] (N symmetric)
    Ncols[k, cols] += 1.0
    post = a - (a[cols] / Ncols[k, cols])[:, None] * Ncols
    post[k, cols] = 0.0
    if (post < lo - BOX_TOL).any() or (post > hi + BOX_TOL).any():
        return 2
    return 0


_COMPILED: dict[str, Callable] = {}


def compiled_box_status() -> Callable:
    """:func:`box_status` compiled by numba (once per process; cached on disk)."""
    if "box" not in _COMPILED:
        import numba

        _COMPILED["box"] = numba.njit(cache=True, nogil=True, error_model="numpy")(box_status)
    return _COMPILED["box"]


def bounded_step(ctrl, name: str, inner: Callable, horizon: float) -> Callable:
    """``step(q, xdot, out=None)``: ``inner`` (the unbounded fast step), inside the rate box.

    ``ctrl`` is the :class:`~fault_tolerance.realtime.Controller` being built. With the numba
    backend the whole step after the Jacobian is one compiled call
    (:func:`fault_tolerance.boxsolve.bounded_kernel`); otherwise, and for every step the compiled
    solve refuses, the reference route: ``inner``, the box check, and
    :func:`~fault_tolerance.bounded.resolve_bounded` only when a bound is met.

    Sets ``ctrl.last_scale`` (task scaling of the last step, 1 when ``ẋ`` was reached) and
    ``ctrl.last_active`` (joints held at a bound); counts ``ctrl.bounded_steps`` (steps that needed
    the bounded solver) and ``ctrl.bounded_reference_steps`` (those solved by the reference).
    """
    if not (np.isfinite(horizon) and horizon > 0):
        raise InvalidInput(f"horizon must be finite and > 0 [s], got {horizon}")
    arm, n = ctrl.arm, ctrl.n
    lim = np.empty((3, n))
    lim[0] = np.where(np.abs(arm.lower) < NO_LIMIT, arm.lower, -np.inf)
    lim[1] = np.where(np.abs(arm.upper) < NO_LIMIT, arm.upper, np.inf)
    lim[2] = velocity_limits(arm)
    prm = np.array([1.0 / horizon, ctrl._alpha])
    reference = _reference_step(ctrl, name, inner, lim, prm)
    if ctrl.backend != "numba":
        return reference
    from .boxfast import compiled_bounded_step

    return compiled_bounded_step(ctrl, name, inner, reference, lim, prm)


def _reference_step(ctrl, name: str, inner: Callable, lim, prm) -> Callable:
    """The reference route: ``inner``, the box check, :func:`resolve_bounded` when a bound is met."""
    n = ctrl.n
    buf = np.empty((4, n))  # lo, hi, scratch (n), scratch (m <= n)
    lo, hi = buf[0], buf[1]
    ws = ctrl._jvja_ws  # [P, Q, c] of the last JVJA fast step, N = I - PᵀQ (set by the kernels)
    jv = name == "jvja" and ctrl._singletons
    cols = ctrl.scenarios.columns if ctrl._singletons else np.zeros(0, dtype=np.int64)
    check = compiled_box_status() if ctrl.backend == "numba" else box_status_numpy
    dummy = np.zeros((ctrl.m, n)), np.zeros((ctrl.m, n)), np.zeros(n)
    sc = ctrl.scenarios
    general = name == "jvja" and not ctrl._singletons

    def slow(q, xdot, out):
        J = ctrl.jacobian(q)
        opts = {"tolerate": ctrl.tolerate}
        if name == "mda":
            opts.update(dJ=ctrl.jacobian_derivatives(q), gain=ctrl.gain, max_step=ctrl.max_step)
        box_status_numpy(q, lim, prm, buf, out, *dummy, cols, False)  # the box (L1) at q
        box = (lo.copy(), hi.copy())
        res = resolve_bounded(name, J, np.asarray(xdot, dtype=float), sc, bounds=box, **opts)
        out[...] = res.qd
        state = ctrl._box_state  # the compiled steps' state when there are any
        state[0], state[1], state[2:] = res.scale, 1.0, res.active
        ctrl.bounded_steps += 1
        ctrl.bounded_reference_steps += 1
        return out

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        before = ctrl.fallbacks
        out = inner(q, xdot, out)
        fresh = jv and ctrl.fallbacks == before
        P, Q, c = (ws[0], ws[1], ws[2]) if fresh else dummy
        status = check(q, lim, prm, buf, out, P, Q, c, cols, fresh)
        if status or general or (jv and not fresh):
            return slow(q, xdot, out)
        state = ctrl._box_state
        state[0], state[1] = 1.0, 0.0
        state[2:] = 0.0
        return out

    step.slow = slow
    step.__name__ = name
    step.__doc__ = f"{name} inside the rate box of the joint limits (reference route)."
    return step


__all__ = ["RATE_HORIZON", "bounded_step", "box_status", "box_status_numpy"]
