"""The bounded step's common case compiled lean: the unbounded step and one box check.

Most steps under joint limits meet no bound. :func:`free_kernel` does exactly what such a step
needs after the Jacobian, in the layout of the unbounded step (:func:`fault_tolerance.control.fast.step.packed_step_kernel`:
one 2-d float workspace taken apart by row slices, no reshapes): LNVA or single-joint JVJA
(:func:`fault_tolerance.control.fast.step.step_kernel`) and the box check (L1)
(:func:`fault_tolerance.control.fast.box_check.box_status`, with every reduced robot's (G1) rates for JVJA).
Only when a bound is met does :func:`fault_tolerance.control.fast.bounded_solve.free_then_bounded`
(which inlines this kernel) go on to the bounded solve, from these rates. Plain Python without
numba.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.control.fast.box_check import g1_column_into
from fault_tolerance.control.fast.step import N_PARAMS, _inline, compiled_kernel
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.resolution.box_qp import BOX_TOL
from fault_tolerance.resolution.fast.box_qp import _njit

_step_kernel = compiled_kernel("step")

#: Rows after the unbounded step's ``4 + 2m``: position and velocity limits (3), the box and its
#: two scratch rows (4), ``[1/h, alpha, mode, k]`` (1), the lockable columns as floats (1).
EXTRA_ROWS = 9


@_njit
def free_shape(m, n):  # pragma: no cover - numba
    """Rows and width of the workspace of :func:`free_kernel`."""
    return 4 + 2 * m + EXTRA_ROWS, max(n, N_PARAMS)


@_njit
def free_kernel(J, q, xdot, out, W, state):  # pragma: no cover - numba
    """LNVA or single-joint JVJA rates into ``out`` and the box check; returns a status.

    ``W`` (:func:`free_workspace`): rows ``params`` (4), ``fw`` (2), ``B`` (m), ``c`` (1), ``G``
    (m) as :func:`fault_tolerance.control.fast.step.packed_step_kernel` reads them, then ``lim``
    (3), ``lo, hi`` and two scratch rows, ``[1/h, alpha, mode, k]`` and the ``k`` lockable
    columns. ``state`` (n + 2) is the bounded step's state, reset when no bound is met. Status 0:
    inside the box (``out`` final); 1: a bound is met (``out`` holds the unbounded rates); 2:
    sizes, or the unbounded step refused (no certificate, a small pivot): the reference route.
    The box check is :func:`fault_tolerance.control.fast.box_check.box_status` (the same
    operations in the same order) on the rows of ``W`` indexed in place: no views, whose
    reference counts cost more than the check of a small arm.
    """
    return _free(J, q, xdot, out, W, state)


@_inline
def _free(J, q, xdot, out, W, state):  # pragma: no cover - numba
    """:func:`free_kernel`'s body, inlined into the one-call bounded step too."""
    m, n = J.shape
    rows, width = free_shape(m, n)
    if xdot.shape[0] != m or out.shape[0] != n or q.shape[0] != n or state.shape[0] != n + 2:
        return 2
    if W.shape[0] != rows or W.shape[1] != width:
        return 2
    h = 4 + 2 * m
    jvja = int(W[h + 7, 2])
    st = _step_kernel(J, xdot, out, W[4 + m : h, :m], W[3 : 3 + m], W[3 + m], W[1:3],
                      W[0, :N_PARAMS], jvja)  # fmt: skip
    if st:
        return 2
    if _outside(q, out, W, h, n) or (jvja == 1 and _reduced_outside(out, W, h, m, n)):
        return 1
    if state[1] != 0.0 or state[0] != 1.0:
        state[0], state[1] = 1.0, 0.0
        for j in range(n):
            state[2 + j] = 0.0
    return 0


# Eqn. (L1): the rate box at q, and whether the rates leave it.
@_inline_once
def _outside(q, out, W, h, n) -> bool:  # pragma: no cover - numba
    """Box (L1) at ``q`` into rows ``h + 3, h + 4`` of ``W``; True when ``out`` leaves it."""
    ih = W[h + 7, 0]
    bad = False
    for j in range(n):
        lj = (W[h, j] - q[j]) * ih
        hj = (W[h + 1, j] - q[j]) * ih
        v = W[h + 2, j]
        lj = -v if lj < -v else (v if lj > v else lj)
        hj = -v if hj < -v else (v if hj > v else hj)
        W[h + 3, j] = lj
        W[h + 4, j] = hj
        if out[j] < lj - BOX_TOL or out[j] > hj + BOX_TOL:
            bad = True
    return bad


# Eqn. (G1) in the box: every reduced robot's rates a − (a_i / N_ii) N[:, i], N = I − YᵀY
# (the column and the pivot by box_check.g1_column_into).
@_inline_once
def _reduced_outside(out, W, h, m, n) -> bool:  # pragma: no cover - numba
    """True when a reduced robot's (G1) rates leave the box (``box_status``'s status 2).

    ``Y = W[3 : 3 + m]``, ``c = W[3 + m]`` (the step's ``N c``), ``alpha = W[h + 7, 1]``; rows
    ``h + 5`` (``a``) and ``h + 6`` (``Y c``, then a column of ``N``) are scratch.
    """
    alpha, k, a, y = W[h + 7, 1], int(W[h + 7, 3]), h + 5, h + 6
    lo, hi, cr = h + 3, h + 4, 3 + m
    for r in range(m):  # N c = c - Yᵀ (Y c), N never formed
        s = 0.0
        for j in range(n):
            s += W[3 + r, j] * W[cr, j]
        W[y, r] = s
    for j in range(n):
        W[a, j] = W[cr, j]
    for r in range(m):
        yr = W[y, r]
        for j in range(n):
            W[a, j] -= W[3 + r, j] * yr
    for j in range(n):
        W[a, j] = out[j] - alpha * W[a, j]
    Y, col = W[3 : 3 + m], W[y]
    for t in range(k):
        i = int(W[h + 8, t])
        ratio = W[a, i] / g1_column_into(Y, Y, m, n, col, i)
        for j in range(n):
            p = W[a, j] - ratio * col[j]
            if j != i and (p < W[lo, j] - BOX_TOL or p > W[hi, j] + BOX_TOL):
                return True
    return False


def free_workspace(n: int, m: int, params, fw, lim, prm, mode: int, cols) -> np.ndarray:
    """The workspace of :func:`free_kernel` (see there), filled with the step's constants."""
    W = np.zeros(free_shape.py_func(m, n))
    h = 4 + 2 * m
    W[0, :N_PARAMS] = params
    W[1:3, :n] = fw
    W[h : h + 3, :n] = lim
    W[h + 7, :4] = prm[0], prm[1], mode, len(cols)
    W[h + 8, : len(cols)] = cols
    return W


__all__ = ["EXTRA_ROWS", "free_kernel", "free_shape", "free_workspace"]
