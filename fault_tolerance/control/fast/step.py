"""The LNVA and single-joint JVJA step in one compiled kernel (numba backend), and the floor.

:func:`step_kernel` is the whole step after the Jacobian as scalar loops: one Cholesky factor of
``G = J Jᵀ`` with the certificate ``trace(G⁻¹) ≤ TRACE_MAX`` (``σ_min(J) ≥ SIGMA_EPS``), then
LNVA ``a = Jᵀ G⁻¹ ẋ``, or JVJA in closed form (G2) with ``Y = L⁻¹J``: ``a = Yᵀ(L⁻¹ẋ)``,
``N_ii = 1 − ‖Y_i‖²``, ``N c = c − Yᵀ(Y c)``, N never formed (O(m² n), linear in n).
:func:`compiled_step` builds a :class:`~fault_tolerance.control.controller.Controller`'s step around it (from its
:class:`~fault_tolerance.control.workspace.ControllerWorkspace`),
with all of its tables in one 2-d float workspace, taken apart by row slices, not reshapes
(:func:`packed_step_kernel`: the fixed cost of a call is the Jacobian, the kernel and the dispatch
of five arguments). ``Y`` and the pivots are built row by row along the rows of Pinocchio's
(C-order) Jacobian, loops that numba vectorises. :func:`floor_kernel` is the
benchmark's floor: least-norm rates by Cholesky and nothing else.

Plain Python without numba (valid, and tested so: ``step_kernel.py_func``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import pinocchio as pin

from fault_tolerance.control.fallback import bad_call as _bad_call
from fault_tolerance.control.fallback import fallback as _fallback
from fault_tolerance.control.lapack_steps import _LWA, _STEP_ERRORS, F64, TRACE_MAX
from fault_tolerance.control.workspace import ControllerWorkspace
from fault_tolerance.errors import FaultToleranceError
from fault_tolerance.fast_cache import inline as _inline
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit as _njit
from fault_tolerance.numerics.fast.dense import (
    forward,
    gram_factor,
    least_norm,
    null_apply,
    rank_ok,
    trace_inverse,
)
from fault_tolerance.numerics.linalg import projection

_INF = math.inf
#: The step's parameters (the first row of its workspace, :func:`workspace`).
N_PARAMS = 4


_factor = gram_factor  # G = J Jᵀ and its Cholesky factor in place (compiled_linalg)
_trace_inverse = trace_inverse  # the certificate trace(G⁻¹)


_forward = forward  # y = L⁻¹ b (compiled_linalg)


@_inline
def _lnva(J, xdot, out, G, c) -> int:  # pragma: no cover - numba
    """LNVA: ``y = G⁻¹ ẋ`` (``L z = ẋ``, ``Lᵀ y = z``, in ``c``), ``a = Jᵀ y``; status."""
    m, n = J.shape
    _forward(G, xdot, c, m)
    for i in range(m - 1, -1, -1):
        t = c[i]
        for k in range(i + 1, m):
            t -= G[k, i] * c[k]
        c[i] = t / G[i, i]
    s = 0.0
    for col in range(n):
        t = 0.0
        for i in range(m):
            t += J[i, col] * c[i]
        out[col] = t
        s += t * t
    return 0 if s < _INF else 1


@_inline
def _pivots(Y, a, c, d, fw, threshold, n) -> bool:  # pragma: no cover - numba
    """``d_i = N_ii = 1 − ‖Y_i‖²`` (``Y_i`` column i), ``c_i = (w_i/W) a_i / N_ii``; True if a pivot is low.

    ``fw[0]``: 0 on lockable columns, +inf elsewhere (then ``N_ii = inf``, ``c_i = 0``). The
    squares are taken off row by row of ``Y`` (vectorised), in the order of a sum per column.
    ``d`` may be ``c`` (the step keeps no pivots; the simulated sample does, for its jumps).
    """
    m = Y.shape[0]
    for i in range(n):
        d[i] = 1.0 + fw[0, i]
    for r in range(m):
        for i in range(n):
            d[i] -= Y[r, i] * Y[r, i]
    low = False
    for i in range(n):
        di = d[i]
        low |= di < threshold
        c[i] = a[i] / di * fw[1, i]
    return low


# Eq. (G2), first half: the factors of the closed-form JVJA step.
@_inline
def jvja_factors(J, xdot, a, L, Y, c, d, fw, params, tr) -> int:  # pragma: no cover - numba
    """``Y = L⁻¹J`` (in ``Y``), ``a = J⁺ẋ = Yᵀ(L⁻¹ẋ)``, the rank certificate, pivots and ratios.

    ``L`` the Cholesky factor of ``J Jᵀ`` and ``tr = trace((J Jᵀ)⁻¹)``; ``c`` (≥ n) gets the ratios
    ``c_i = (w_i/W) a_i / N_ii``, ``d`` (≥ n, may be ``c``) the pivots ``N_ii``. Status 0; 1: no
    rank certificate; 2: a pivot below ``params[1]``. Shared by :func:`step_kernel` and the
    simulated sample (:mod:`fault_tolerance.simulation.fast.sample`).
    """
    n = J.shape[1]
    least_norm(J, xdot, L, Y, c, a)  # Y = L⁻¹ J (in Y) and z = L⁻¹ ẋ (in c): a = Yᵀ z
    if not rank_ok(J, tr, params[2]):  # rank certificate (linalg.RANK_RTOL), arms without a bound
        return 1
    if _pivots(Y, a, c, d, fw, params[1], n):
        return 2
    return 0


# Eq. (G2), second half: a + alpha N c, N = I − YᵀY never formed.
@_inline
def jvja_rates(Y, a, out, c, u, alpha, n) -> int:  # pragma: no cover - numba
    """``out = a + alpha N c`` (``c ← N c``, ``u`` (m) scratch; ``out`` may be ``a``); 0, or 1 if not finite."""
    null_apply(Y, c, u, n)
    s2 = 0.0
    for i in range(n):
        out[i] = a[i] + alpha * c[i]
        s2 += out[i] * out[i]
    return 0 if s2 < _INF else 1


@_inline
def _jvja(J, xdot, out, G, B, c, fw, params, tr) -> int:  # pragma: no cover - numba
    """JVJA (G2): ``out = a + alpha N c``, ``c_i = (w_i/W) a_i / N_ii`` on lockable columns."""
    status = jvja_factors(J, xdot, out, G, B, c, c, fw, params, tr)
    if status:
        return status
    # c ← N c (the factor is no longer needed: its row 0 is scratch)
    return jvja_rates(B, out, out, c, G[0], params[3], J.shape[1])


@_njit
def step_kernel(J, xdot, out, G, B, c, fw, params, jvja):  # pragma: no cover - numba
    """LNVA (``jvja=0``) or single-joint JVJA (``jvja=1``) rates into ``out``; returns a status.

    ``params = [TRACE_MAX, pivot threshold, rank coefficient, alpha]``; ``fw[0]`` is 0 on
    lockable columns and +inf elsewhere, ``fw[1]`` the weight ``w_i/W`` (or 1 with uniform
    weights, then ``alpha = -1/f``); ``G`` (m, m), ``B`` (m, ≥ n), ``c`` (≥ n) scratch. Status 0:
    done; 1: no certificate of ``σ_min ≥ SIGMA_EPS`` (or non-finite numbers), the caller falls
    back to the planner; 2: a pivot ``N_ii`` is below the threshold (``PIVOT_TOL``: intolerable;
    ``PIVOT_EPS`` with ``tolerate``: to be damped by the planner). Status 3: ``xdot`` or ``out``
    has the wrong size (nothing written).
    """
    return _step(J, xdot, out, G, B, c, fw, params, jvja)


@_inline
def _step(J, xdot, out, G, B, c, fw, params, jvja):  # pragma: no cover - numba
    """:func:`step_kernel`'s body, inlined into :func:`packed_step_kernel` too."""
    m, n = J.shape
    if xdot.shape[0] != m or out.shape[0] != n:
        return 3
    if not _factor(J, G):
        return 1
    tr = _trace_inverse(G, c, m)
    if not tr <= params[0]:
        return 1
    if not jvja:
        return _lnva(J, xdot, out, G, c)
    return _jvja(J, xdot, out, G, B, c, fw, params, tr)


@_njit
def packed_step_kernel(J, xdot, out, ws, jvja):  # pragma: no cover - numba
    """:func:`step_kernel` with its tables in one workspace ``ws`` (:func:`workspace`).

    Five arguments per call (the Controller's step); status 3 also when ``ws`` has the wrong shape.
    """
    m, n = J.shape
    rows, width = workspace_shape(m, n)
    if ws.shape[0] != rows or ws.shape[1] != width:
        return 3
    params, fw, G, B, c = _views(ws, m, n)
    return _step(J, xdot, out, G, B, c, fw, params, jvja)


@_inline_once
def workspace_shape(m, n):  # pragma: no cover - numba
    """Rows and width of the workspace of :func:`packed_step_kernel` (a 2-d C array).

    Rows: ``params`` (its first :data:`N_PARAMS` entries), ``fw`` (2), ``B`` (m), ``c`` (1),
    ``G`` (m); width ``max(n, m, 4)``.
    """
    return 4 + 2 * m, max(n, m, N_PARAMS)


@_njit
def _views(ws, m, n):  # pragma: no cover - numba
    """``params, fw, G, B, c`` in the workspace, as row slices (no reshape, nothing copied).

    ``fw``, ``G``, ``B`` and ``c`` are whole rows (C order: the kernels' loops along them
    vectorise and index them without strides), ``width - n`` (``G``: ``width - m``) columns wider
    than their tables; the kernels loop to ``n`` (``m``).
    """
    return ws[0, :N_PARAMS], ws[1:3], ws[4 + m : 4 + 2 * m], ws[3 : 3 + m], ws[3 + m]


def workspace(cw: ControllerWorkspace) -> tuple[np.ndarray, tuple]:
    """The workspace of ``cw``'s compiled step and its views ``(params, fw, G, B, c)``.

    Laid out as :func:`packed_step_kernel` reads it; the views returned here are exactly
    ``(4,), (2, n), (m, m), (m, n), (n,)``.
    """
    m, n = cw.m, cw.n
    ws = np.zeros(workspace_shape.py_func(m, n))
    params, fw, G, B, c = _views.py_func(ws, m, n)
    views = params, fw[:, :n], G[:, :m], B[:, :n], c[:n]
    params[:] = TRACE_MAX, cw.pivot_threshold, cw.rank_coef, cw.alpha
    views[1][:] = cw.fw
    return ws, views


# The floor of a control step after the Jacobian: least-norm rates with no check at all.
def floor_kernel(J, xdot, out, G, y):  # pragma: no cover - numba
    """``out = Jᵀ (J Jᵀ)⁻¹ ẋ`` by Cholesky, nothing else (the benchmark's floor)."""
    m, n = J.shape
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += J[i, k] * J[j, k]
            G[i, j] = s
    for j in range(m):
        s = G[j, j]
        for k in range(j):
            s -= G[j, k] * G[j, k]
        s = math.sqrt(s)
        G[j, j] = s
        for i in range(j + 1, m):
            t = G[i, j]
            for k in range(j):
                t -= G[i, k] * G[j, k]
            G[i, j] = t / s
    for i in range(m):
        t = xdot[i]
        for k in range(i):
            t -= G[i, k] * y[k]
        y[i] = t / G[i, i]
    for i in range(m - 1, -1, -1):
        t = y[i]
        for k in range(i + 1, m):
            t -= G[k, i] * y[k]
        y[i] = t / G[i, i]
    for col in range(n):
        t = 0.0
        for i in range(m):
            t += J[i, col] * y[i]
        out[col] = t


_COMPILED: dict[str, Callable] = {}


def compiled_kernel(name: str = "step") -> Any:
    """:func:`step_kernel` compiled by numba, once (also ``"packed"`` and ``"floor"``).

    The result is a numba dispatcher (untyped: it has ``disable_compile`` besides ``__call__``).

    ``"packed"``: :func:`packed_step_kernel`; ``"floor"``: :func:`floor_kernel`.

    The floor is one self-contained function (no calls), compiled here.
    """
    if name in ("step", "packed"):
        import numba  # noqa: F401 - raises ImportError here when numba is missing

        return step_kernel if name == "step" else packed_step_kernel
    if name not in _COMPILED:
        fn = {"floor": floor_kernel}[name]
        _COMPILED[name] = _njit(fn)
    return _COMPILED[name]


def compiled_step(cw: ControllerWorkspace, jvja: int) -> Callable[..., np.ndarray]:
    """The LNVA (``jvja=0``) or single-joint JVJA (``jvja=1``) step of ``cw``, numba-compiled.

    Compiles :func:`step_kernel` on first use (here, not in the loop) and runs it once.
    """
    model, data, fid, rows = cw.model, cw.data, cw.frame_id, cw.rows
    n, m = cw.n, cw.m
    kernel = compiled_kernel("packed")
    cfj, empty, ndarray = pin.computeFrameJacobian, np.empty, np.ndarray
    ws, (_, _, _, B, c) = workspace(cw)
    shape_n, shape_m = (n,), (m,)
    bad_call = partial(_bad_call, cw)
    name = "jvja" if jvja else "lnva"
    if jvja:  # N = I - YᵀY with Y = L⁻¹J in B, for the bounded step's box check (boxstep)
        cw.jvja_factors[0], cw.jvja_factors[1], cw.jvja_factors[2] = B, B, c
    # Compile for this arm's Jacobian layout (here, not in the loop), then freeze the dispatcher:
    # an argument of another type or layout raises TypeError (then `slow`) instead of compiling,
    # so the step needs no type checks of its own.
    J0 = cfj(model, data, pin.neutral(model), fid, _LWA)[rows]
    kernel.disable_compile(False)
    kernel(J0, np.zeros(m), np.zeros(n), np.zeros(ws.shape), jvja)
    kernel.disable_compile(True)

    def slow(q, xdot, out, err: Exception) -> np.ndarray:
        """A call the compiled kernel refused (types, shapes): convert ``xdot`` once, or say why."""
        if type(out) is ndarray and out.shape == shape_n and out.dtype == F64:
            if out.flags.c_contiguous and not (
                type(xdot) is ndarray and xdot.dtype == F64 and xdot.flags.c_contiguous
            ):
                x2 = np.ascontiguousarray(xdot, dtype=float)
                if x2.shape == shape_m:
                    return step(q, x2, out)
        raise bad_call(err, q, xdot, out) from err

    refused = refusal_route(cw, name, slow)

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        if out is None:
            out = empty(n)
        try:  # the kernel checks the sizes (status 3); numba the types and layouts (TypeError)
            status = kernel(cfj(model, data, q, fid, _LWA)[rows], xdot, out, ws, jvja)
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            return slow(q, xdot, out, err)
        if status:
            return refused(status, q, xdot, out)
        return out

    step.__name__ = name
    step.__doc__ = (
        "JVJA, minimum square-sum jump rates, eq. (5) in closed form (G2); compiled."
        if jvja
        else "LNVA, least-norm rates ``q̇ = J⁺ẋ``; compiled."
    )
    return step


def refusal_route(cw: ControllerWorkspace, name: str, slow: Callable) -> Callable[..., np.ndarray]:
    """``route(status, q, xdot, out)``: what a compiled step of ``cw`` does with a refused call.

    Status 3 (sizes) goes to ``slow``; 1 (no certificate) and 2 (a pivot below the threshold) to
    the planner's step, after the tolerability check that names the joints (``tolerate=False``).
    Shared by the single- and multi-joint steps.
    """
    model, data, fid, rows = cw.model, cw.data, cw.frame_id, cw.rows
    cfj, fallback, tolerate = pin.computeFrameJacobian, partial(_fallback, cw), cw.tolerate
    check_tolerable = cw.scenarios.check_tolerable

    def route(status: int, q, xdot, out) -> np.ndarray:
        if status == 3:
            return slow(q, xdot, out, ValueError("shape"))
        J = cfj(model, data, q, fid, _LWA)[rows]
        if status == 2 and not tolerate:
            check_tolerable(projection(J).N)  # raises IntolerableFailure naming the joints
        return fallback(name, J, xdot, out)

    return route
