"""The JVJA step for any scenarios, multi-joint ones too (G1), in one compiled kernel.

:func:`multi_kernel` is :func:`fault_tolerance.control.fast.step.step_kernel`'s JVJA for scenarios of any
size: with ``Y = L⁻¹J`` (``G = J Jᵀ = L Lᵀ``) every ``N[S, S] = I − Y_Sᵀ Y_S`` is an s x s matrix
built in O(m s²), factored by Cholesky (a scenario is refused or handed to the planner when
``N[S, S] − threshold·I`` is not positive definite, i.e. its smallest eigenvalue is below the
threshold), and ``q̇ = a − N c``, ``c = Σ_S (w_S/W) E_S N[S,S]⁻¹ a_S``, with ``N c = c − Yᵀ(Y c)``:
N is never formed. Used by :class:`fault_tolerance.control.controller.Controller` with the numba backend.
Plain Python without numba (and tested so).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin

from fault_tolerance.control.fallback import bad_call as _bad_call
from fault_tolerance.control.fast.step import _factor, _trace_inverse, refusal_route
from fault_tolerance.control.workspace import ControllerWorkspace
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit as _njit
from fault_tolerance.numerics.fast.dense import (
    chol_solve,
    cholesky,
    least_norm,
    null_apply,
    rank_ok,
)

_LWA = pin.LOCAL_WORLD_ALIGNED
_F64 = np.dtype(np.float64)


@_njit
def _chol(A, L, s, shift) -> bool:  # pragma: no cover - numba
    """Lower Cholesky factor of ``A[:s, :s] − shift·I`` into ``L``; False unless PD."""
    for i in range(s):
        for j in range(i):
            L[i, j] = A[i, j]
        L[i, i] = A[i, i] - shift
    return cholesky(L, s)


@_njit
def multi_kernel(J, xdot, out, ws, sets, wrel, params) -> int:  # pragma: no cover - numba
    """JVJA rates into ``out`` for the scenarios ``sets`` (f, s_max; -1 pads); a status.

    ``params = [TRACE_MAX, pivot threshold, rank coefficient]``; ``wrel`` the weights over their
    sum; ``ws`` a float workspace of ``m² + m n + n + 2 s_max² + 2 s_max`` numbers. Status 0:
    done; 1: no certificate of ``σ_min ≥ SIGMA_EPS`` (or not finite): the planner's step;
    2: a scenario's ``N[S, S]`` has an eigenvalue below the threshold; 3: wrong sizes.
    """
    m, n = J.shape
    if xdot.shape[0] != m or out.shape[0] != n:
        return 3
    smax = sets.shape[1]
    G = ws[0 : m * m].reshape((m, m))
    Y = ws[m * m : m * m + m * n].reshape((m, n))
    o = m * m + m * n
    c = ws[o : o + n]
    A = ws[o + n : o + n + smax * smax].reshape((smax, smax))
    L = ws[o + n + smax * smax : o + n + 2 * smax * smax].reshape((smax, smax))
    x = ws[o + n + 2 * smax * smax : o + n + 2 * smax * smax + smax]
    if not _factor(J, G):
        return 1
    tr = _trace_inverse(G, c, m)  # trace(G⁻¹) = ‖L⁻¹‖_F², the certificate (c as scratch)
    if not tr <= params[0]:
        return 1
    if not rank_ok(J, tr, params[2]):
        return 1
    least_norm(J, xdot, G, Y, c, out)
    for i in range(n):
        c[i] = 0.0
    for k in range(sets.shape[0]):
        if not _scenario_shift(Y, out, sets[k], wrel[k], params[1], A, L, x, c):
            return 2
    return _minus_null(Y, G, c, out)


@_inline_once
def _scenario_shift(Y, a, S, w, threshold, A, L, x, c) -> bool:  # pragma: no cover - numba
    """``c += w E_S N[S, S]⁻¹ a_S`` (G1) for one scenario ``S`` (-1 pads); False below threshold."""
    m, smax = Y.shape[0], S.shape[0]
    s = 0
    while s < smax and S[s] >= 0:
        s += 1
    for p in range(s):  # N[S, S] = I - Y_Sᵀ Y_S
        for q in range(p + 1):
            t = 1.0 if p == q else 0.0
            for r in range(m):
                t -= Y[r, S[p]] * Y[r, S[q]]
            A[p, q] = t
            A[q, p] = t
    if not _gershgorin_above(A, s, threshold) and not _chol(A, L, s, threshold):
        return False
    _chol(A, L, s, 0.0)
    for p in range(s):  # x = N[S, S]⁻¹ a_S
        x[p] = a[S[p]]
    chol_solve(L, s, x)
    for p in range(s):
        c[S[p]] += w * x[p]
    return True


@_inline_once
def _gershgorin_above(A, s, threshold) -> bool:  # pragma: no cover - numba
    """Whether every Gershgorin disc of ``A[:s, :s]`` lies above ``threshold`` (with a margin).

    Then ``A − threshold·I`` is positive definite and its Cholesky test is not needed; when a disc
    reaches the threshold the test decides.
    """
    for p in range(s):
        t = A[p, p]
        for q in range(s):
            if q != p:
                t -= abs(A[p, q])
        if not t > threshold * (1.0 + 1e-8) + 1e-14:
            return False
    return True


@_inline_once
def _minus_null(Y, G, c, out) -> int:  # pragma: no cover - numba
    """``out = a - N c = a - c + Yᵀ (Y c)`` (G's first column as scratch); status 0, or 1."""
    n = Y.shape[1]
    null_apply(Y, c, G[:, 0], n)
    total = 0.0
    for i in range(n):
        out[i] -= c[i]
        total += out[i] * out[i]
    return 0 if total < math.inf else 1


def compiled_multi_step(cw: ControllerWorkspace) -> Callable[..., np.ndarray]:
    """The compiled JVJA step of a Controller (its workspace ``cw``), scenarios of any size."""
    from fault_tolerance.control.lapack_steps import TRACE_MAX

    model, data, fid, rows = cw.model, cw.data, cw.frame_id, cw.rows
    n, m, sc = cw.n, cw.m, cw.scenarios
    smax = max(len(S) for S in sc.sets)
    sets = -np.ones((sc.f, smax), dtype=np.int64)
    for k, S in enumerate(sc.sets):
        sets[k, : len(S)] = S
    w = sc.weights / sc.weights.max()  # scale-free; the sum cannot overflow
    wrel = np.ascontiguousarray(w / w.sum())
    params = np.array([TRACE_MAX, cw.pivot_threshold, cw.rank_coef])
    ws = np.zeros(m * m + m * n + n + 2 * smax * smax + 2 * smax)
    cfj, ndarray = pin.computeFrameJacobian, np.ndarray
    bad_call = partial(_bad_call, cw)
    multi_kernel(np.zeros((m, n)), np.zeros(m), np.zeros(n), ws, sets, wrel, params)  # compile

    def slow(q, xdot, out, err):
        if type(out) is ndarray and out.shape == (n,) and out.dtype is _F64:
            x2 = np.asarray(xdot, dtype=float)
            if x2.shape == (m,) and not (type(xdot) is ndarray and xdot.dtype is _F64):
                return jvja(q, np.ascontiguousarray(x2), out)
        raise bad_call(err, q, xdot, out) from err

    refused = refusal_route(cw, "jvja", slow)

    def jvja(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """JVJA, minimum square-sum jump rates, eq. (5) (G1, any scenarios); compiled."""
        if out is None:
            out = np.empty(n)
        if type(out) is not ndarray or type(xdot) is not ndarray or out.dtype is not _F64:
            return slow(q, xdot, out, TypeError("not a float64 array"))
        if xdot.dtype is not _F64:
            return slow(q, xdot, out, TypeError("not a float64 array"))
        try:
            status = multi_kernel(cfj(model, data, q, fid, _LWA)[rows], xdot, out, ws, sets,
                                  wrel, params)  # fmt: skip
        except (ValueError, TypeError, RuntimeError, AttributeError, IndexError) as err:
            return slow(q, xdot, out, err)
        if status:
            return refused(status, q, xdot, out)
        return out

    return jvja
