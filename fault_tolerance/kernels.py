"""Backend kernels of :class:`~fault_tolerance.realtime.Controller`: each step, per backend.

* The LAPACK/BLAS calls of a step from ``scipy.linalg`` (:func:`lapack_linalg`), or done by
  NumPy with the same signatures and results (:func:`numpy_linalg`).
* :func:`step_kernel`: the whole LNVA / single-joint JVJA step after the Jacobian, as scalar
  loops; :func:`compiled_kernel`: that kernel compiled by numba (imported then; cached on disk).
* The step builders :func:`lapack_lnva`, :func:`lapack_jvja`, :func:`lapack_mda` and
  :func:`compiled_step`: each reads a built controller's workspace (scenario tables, thresholds,
  linear-algebra calls ``_la``) and returns its ``step(q, xdot, out=None) -> qd`` closure.

Every step certifies ``σ_min(J) ≥ SIGMA_EPS`` by ``trace((J Jᵀ)⁻¹) ≤ TRACE_MAX``, or hands the
step to the controller's ``_fallback`` (the planner, damped): see :mod:`fault_tolerance.realtime`.
Importing this module imports neither numba nor scipy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import SimpleNamespace
from typing import Protocol

import numpy as np
import pinocchio as pin

from .errors import FaultToleranceError
from .linalg import SIGMA_EPS, projection

__all__ = [
    "TRACE_MAX",
    "Workspace",
    "compiled_kernel",
    "compiled_step",
    "lapack_jvja",
    "lapack_linalg",
    "lapack_linalg_or_numpy",
    "lapack_lnva",
    "lapack_mda",
    "numpy_linalg",
    "step_kernel",
]

#: ``trace((J Jᵀ)⁻¹)`` up to which ``σ_min(J) ≥ SIGMA_EPS`` is certain, so no damping is needed.
TRACE_MAX = 1.0 / SIGMA_EPS**2

_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD
_INF = float("inf")
_STEP_ERRORS = (ValueError, TypeError, RuntimeError, AttributeError, IndexError)
F64 = np.dtype(np.float64)


class Workspace(Protocol):
    """What the step builders read: a built :class:`~fault_tolerance.realtime.Controller`.

    Declared here so that this module does not import :mod:`fault_tolerance.realtime` (which
    imports it).
    """

    model: pin.Model
    data: pin.Data
    frame_id: int
    n: int
    m: int
    tolerate: bool
    gain: float
    max_step: float
    scenarios: object  # failures.Scenarios
    _rows: slice | np.ndarray
    _la: SimpleNamespace
    _fw: np.ndarray
    _rank_coef: float
    _alpha: float
    _pivot_threshold: float
    _singletons: bool
    _uniform: bool
    _all_uniform: bool

    def _fallback(self, name: str, J, xdot, out, q=None) -> np.ndarray: ...
    def _bad_call(self, err: Exception, q, xdot, out) -> Exception: ...
    def _shift_general(
        self, J: np.ndarray, B: np.ndarray, a: np.ndarray, c: np.ndarray
    ) -> bool: ...
    def _djac(self, Jw: np.ndarray, Jl: np.ndarray, p: np.ndarray) -> np.ndarray: ...
    def rcn_gradient(self, J: np.ndarray, dJ: np.ndarray) -> np.ndarray:
        """Gradient of the square-sum RCN ``K``, shape (n,)."""
        ...


# -- linear algebra backends -----------------------------------------------------------------


def numpy_linalg() -> SimpleNamespace:
    """The LAPACK/BLAS calls of a step, with scipy's signatures and results, done by NumPy."""

    def dsyrk(alpha, a, beta=0.0, c=None, trans=0, lower=0, overwrite_c=0):
        return alpha * (a.T @ a if trans else a @ a.T)

    def dposv(a, b, lower=0, overwrite_a=0):
        try:  # info 1, as LAPACK's, instead of "Singular matrix": the caller falls back (damped)
            U = np.linalg.cholesky(a).T  # upper factor, G = UᵀU; raises unless G is PD
            return U, np.linalg.solve(a, b), 0
        except np.linalg.LinAlgError:
            return a, b, 1

    def dtrtri(c, lower=0, unitdiag=0, overwrite_c=0):
        try:
            return np.triu(np.linalg.inv(c)), 0
        except np.linalg.LinAlgError:
            return c, 1

    def dgemm(alpha, a, b, beta, c):
        return beta * c + alpha * (a @ b)

    def dgemv(
        alpha, a, x, beta=0.0, y=None, offx=0, incx=1, offy=0, incy=1, trans=0, overwrite_y=0
    ):
        r = alpha * ((a.T if trans else a) @ x)
        if y is None:
            return r
        y *= beta
        y += r
        return y

    def ddot(x, y):
        return float(np.vdot(x, y))

    return SimpleNamespace(
        name="numpy", dsyrk=dsyrk, dposv=dposv, dtrtri=dtrtri, dgemm=dgemm, dgemv=dgemv, ddot=ddot
    )


def lapack_linalg() -> SimpleNamespace:
    """The same calls from scipy.linalg's LAPACK/BLAS wrappers."""
    from scipy.linalg import blas, lapack

    return SimpleNamespace(
        name="lapack",
        dsyrk=blas.dsyrk,
        dposv=lapack.dposv,
        dtrtri=lapack.dtrtri,
        dgemm=blas.dgemm,
        dgemv=blas.dgemv,
        ddot=blas.ddot,
    )


def lapack_linalg_or_numpy() -> SimpleNamespace:
    """:func:`lapack_linalg`, or :func:`numpy_linalg` where scipy is not installed."""
    try:
        return lapack_linalg()
    except ImportError:
        return numpy_linalg()


# Eqn. (5) in closed form (G2), one step after the Jacobian; compiled by numba.
def step_kernel(J, xdot, out, G, B, c, fw, params, jvja):  # pragma: no cover - numba
    """LNVA (``jvja=0``) or single-joint JVJA (``jvja=1``) rates into ``out``; returns a status.

    ``params = [TRACE_MAX, pivot threshold, rank coefficient, alpha]``; ``fw[0]`` is 0 on lockable
    columns and +inf elsewhere, ``fw[1]`` the weight ``w_i/W`` (or 1 with uniform weights, then
    ``alpha = -1/f``). Status 0: done; 1: no certificate of ``σ_min ≥ SIGMA_EPS`` (or non-finite
    numbers), the caller falls back to the planner; 2: a pivot ``N_ii`` is below the threshold
    (``PIVOT_TOL``: intolerable; ``PIVOT_EPS`` with ``tolerate``: to be damped by the planner).
    Status 3: ``xdot`` or ``out`` has the wrong size (nothing written).
    Plain Python (valid without numba, and tested so): only scalar loops.
    """
    m, n = J.shape
    if xdot.shape[0] != m or out.shape[0] != n:
        return 3
    # G = J Jᵀ (lower triangle) and its Cholesky factor L, in place.
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
        if not s > 0.0:
            return 1
        s = math.sqrt(s)
        G[j, j] = s
        for i in range(j + 1, m):
            t = G[i, j]
            for k in range(j):
                t -= G[i, k] * G[j, k]
            G[i, j] = t / s
    # trace(G⁻¹) = ‖L⁻¹‖_F², column by column of L⁻¹ (c as scratch): the certificate.
    tr = 0.0
    for j in range(m):
        for i in range(j, m):
            t = 1.0 if i == j else 0.0
            for k in range(j, i):
                t -= G[i, k] * c[k]
            c[i] = t / G[i, i]
            tr += c[i] * c[i]
    if not tr <= params[0]:
        return 1
    if not jvja:
        # LNVA: y = G⁻¹ ẋ (L z = ẋ, Lᵀ y = z, in c), a = Jᵀ y.
        for i in range(m):
            t = xdot[i]
            for k in range(i):
                t -= G[i, k] * c[k]
            c[i] = t / G[i, i]
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
        if not s < _INF:
            return 1
        return 0
    # JVJA: Y = L⁻¹ J (in B) and z = L⁻¹ ẋ (in c), forward substitutions only: a = Yᵀ z,
    # N_ii = 1 - ‖Y_i‖², N c = c - Yᵀ (Y c). N is never formed: O(m² n), linear in n.
    for col in range(n):
        for i in range(m):
            t = J[i, col]
            for k in range(i):
                t -= G[i, k] * B[k, col]
            B[i, col] = t / G[i, i]
    for i in range(m):
        t = xdot[i]
        for k in range(i):
            t -= G[i, k] * c[k]
        c[i] = t / G[i, i]
    for col in range(n):
        s = 0.0
        for i in range(m):
            s += B[i, col] * c[i]
        out[col] = s
    if params[2] > 0.0:  # rank certificate (linalg.RANK_RTOL) for arms without a static bound
        s = 0.0
        for i in range(m):
            for k in range(n):
                s += J[i, k] * J[i, k]
        if not params[2] * s * tr < 1.0:
            return 1
    # c_i = (w_i / W) a_i / N_ii on lockable columns; out = a + alpha N c.
    for i in range(n):
        d = 1.0 + fw[0, i]
        for r in range(m):
            d -= B[r, i] * B[r, i]
        if d < params[1]:
            return 2
        c[i] = out[i] / d * fw[1, i]
    alpha = params[3]
    for r in range(m):
        s = 0.0
        for i in range(n):
            s += B[r, i] * c[i]
        G[r, 0] = s  # the factor is no longer needed: its first column is scratch
    for i in range(n):
        s = c[i]
        for r in range(m):
            s -= B[r, i] * G[r, 0]
        out[i] += alpha * s
    s = 0.0
    for i in range(n):
        s += out[i] * out[i]
    if not s < _INF:
        return 1
    return 0


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


def compiled_kernel(name: str = "step") -> Callable:
    """:func:`step_kernel` (or ``"floor"``: :func:`floor_kernel`) compiled by numba, once."""
    if name not in _COMPILED:
        import numba

        fn = {"step": step_kernel, "floor": floor_kernel}[name]
        _COMPILED[name] = numba.njit(cache=True, nogil=True, error_model="numpy")(fn)
    return _COMPILED[name]


# -- LNVA / JVJA / MDA with LAPACK (or NumPy) calls --------------------------------------------


def lapack_lnva(ctrl: Workspace) -> Callable[..., np.ndarray]:
    """The LNVA step of ``ctrl`` with its LAPACK (or NumPy) calls: ``lnva(q, xdot, out=None)``."""
    model, data, fid, rows = ctrl.model, ctrl.data, ctrl.frame_id, ctrl._rows
    n, m = ctrl.n, ctrl.m
    la = ctrl._la
    dsyrk, dposv, dtrtri, ddot = la.dsyrk, la.dposv, la.dtrtri, la.ddot
    cfj, dot, empty = pin.computeFrameJacobian, np.dot, np.empty
    GT = np.zeros((m, m), order="F")  # LAPACK works in its upper triangle; the rest stays 0
    fallback, bad_call = ctrl._fallback, ctrl._bad_call

    def lnva(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """LNVA, least-norm rates ``q̇ = J⁺ẋ`` (damped near singularities as in linalg)."""
        if out is None:
            out = empty(n)
        try:
            J = cfj(model, data, q, fid, _LWA)[rows]
            G = dsyrk(1.0, J.T, 0.0, GT, 1, 0, 1)  # G = J Jᵀ
            U, y, info = dposv(G, xdot, 0, 1)  # G = UᵀU, y = G⁻¹ẋ: one factorisation
            if info:
                return fallback("lnva", J, xdot, out)
            Ui, info = dtrtri(U, 0, 0, 1)
            if info or not ddot(Ui, Ui) <= TRACE_MAX:  # ‖U⁻¹‖² = trace(G⁻¹); NaN fails too
                return fallback("lnva", J, xdot, out)
            dot(y, J, out=out)  # a = J⁺ẋ = Jᵀy
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            raise bad_call(err, q, xdot, out) from err
        if not ddot(out, out) < _INF:
            return fallback("lnva", J, xdot, out)
        return out

    return lnva


def lapack_jvja(ctrl: Workspace) -> Callable[..., np.ndarray]:
    """The JVJA step of ``ctrl`` with its LAPACK (or NumPy) calls, any scenarios (G1, G2)."""
    model, data, fid, rows = ctrl.model, ctrl.data, ctrl.frame_id, ctrl._rows
    n, m = ctrl.n, ctrl.m
    la = ctrl._la
    dsyrk, dposv, dtrtri, ddot = la.dsyrk, la.dposv, la.dtrtri, la.ddot
    dgemv = la.dgemv
    cfj, dot, empty = pin.computeFrameJacobian, np.dot, np.empty
    divide, multiply, add, subtract, einsum = np.divide, np.multiply, np.add, np.subtract, np.einsum
    GT = np.zeros((m, m), order="F")
    c, d, dF = np.empty(n), np.empty(n), np.empty(n)
    off, wrel = ctrl._fw[0], ctrl._fw[1]
    rank_coef, alpha = ctrl._rank_coef, ctrl._alpha
    fallback, bad_call, general = ctrl._fallback, ctrl._bad_call, ctrl._shift_general
    tol, tolerate = ctrl._pivot_threshold, ctrl.tolerate
    check_tolerable = ctrl.scenarios.check_tolerable
    mode = ("all" if ctrl._all_uniform else "singletons") if ctrl._singletons else "general"
    weighted = not ctrl._uniform
    ws = ctrl._jvja_ws
    ws[2] = c

    def jvja(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """JVJA, minimum square-sum jump rates, eq. (5) in closed form (G1, G2)."""
        if out is None:
            out = empty(n)
        try:
            J = cfj(model, data, q, fid, _LWA)[rows]
            G = dsyrk(1.0, J.T, 0.0, GT, 1, 0, 1)
            U, B, info = dposv(G, J, 0, 1)
            if info:
                return fallback("jvja", J, xdot, out)
            Ui, info = dtrtri(U, 0, 0, 1)
            tr = ddot(Ui, Ui)
            rank_ok = not rank_coef or rank_coef * ddot(J, J) * tr < 1.0
            if info or not tr <= TRACE_MAX or not rank_ok:  # NaN fails too
                return fallback("jvja", J, xdot, out)
            dot(xdot, B, out=out)  # a
            einsum("ij,ij->j", J, B, out=d)  # N is never formed: N_ii = 1 - J_iᵀ B_i
            subtract(1.0, d, out=d)
            ws[0], ws[1] = J, B  # N = I - JᵀB, for the bounded step's box check (boxstep)
            if mode == "all":  # c_i = a_i / N_ii, alpha = -1/f
                if min(d.tolist()) < tol:
                    if not tolerate:
                        check_tolerable(projection(J).N)  # raises, naming the joint
                    return fallback("jvja", J, xdot, out)  # pivots damped by the planner
                divide(out, d, out=c)
            elif mode == "singletons":
                add(d, off, out=dF)
                if min(dF.tolist()) < tol:
                    if not tolerate:
                        check_tolerable(projection(J).N)
                    return fallback("jvja", J, xdot, out)
                divide(out, dF, out=c)
                if weighted:
                    multiply(c, wrel, out=c)
            elif not general(J, B, out, c):
                return fallback("jvja", J, xdot, out)
            y = dgemv(1.0, B, c)  # a + alpha N c = a + alpha c - alpha Jᵀ (B c), in place
            r = dgemv(-alpha, J, y, 1.0, out, 0, 1, 0, 1, 1, 1)
            multiply(c, alpha, out=c)
            add(r, c, out=r)
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            raise bad_call(err, q, xdot, out) from err
        if r is not out:  # pragma: no cover - BLAS wrote a copy (np.dot accepted out)
            out[...] = r
        if not ddot(out, out) < _INF:
            return fallback("jvja", J, xdot, out)
        return out

    return jvja


def lapack_mda(ctrl: Workspace) -> Callable[..., np.ndarray]:
    """The MDA step of ``ctrl`` with its LAPACK (or NumPy) calls: ``mda(q, xdot, out=None)``."""
    model, data, fid, rows = ctrl.model, ctrl.data, ctrl.frame_id, ctrl._rows
    n, m = ctrl.n, ctrl.m
    la = ctrl._la
    dsyrk, dposv, dtrtri, ddot = la.dsyrk, la.dposv, la.dtrtri, la.ddot
    dgemm, dgemv = la.dgemm, la.dgemv
    GT = np.zeros((m, m), order="F")
    eye = np.asfortranarray(np.eye(n))
    fallback, bad_call = ctrl._fallback, ctrl._bad_call
    djac, grad_of = ctrl._djac, ctrl.rcn_gradient
    rank_coef = ctrl._rank_coef
    gain, max_step = ctrl.gain, ctrl.max_step
    oMf = data.oMf

    def mda(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """MDA, maximum-dexterity rates ``q̇ = J⁺ẋ - α N ∇K``."""
        if out is None:
            out = np.empty(n)
        try:
            pin.computeJointJacobians(model, data, q)
            Jw = pin.getFrameJacobian(model, data, fid, _WORLD)
            Jl = pin.getFrameJacobian(model, data, fid, _LWA)
            J = Jl[rows]
            G = dsyrk(1.0, J.T, 0.0, GT, 1, 0, 1)
            U, B, info = dposv(G, J, 0, 1)
            if info:
                return fallback("mda", J, xdot, out, q)
            Ui, info = dtrtri(U, 0, 0, 1)
            tr = ddot(Ui, Ui)
            rank_ok = not rank_coef or rank_coef * ddot(J, J) * tr < 1.0
            if info or not tr <= TRACE_MAX or not rank_ok:  # NaN fails too
                return fallback("mda", J, xdot, out, q)
            np.dot(xdot, B, out=out)
            N = dgemm(-1.0, J.T, B, 1.0, eye)
            grad = grad_of(J, djac(Jw, Jl, oMf[fid].translation))
            step = dgemv(gain, N, grad)  # α N ∇K [rad/s], capped as planner.mda does
            size = math.sqrt(ddot(step, step))
            if not size < _INF:  # ∇K overflowed at a reduced singularity: no direction
                step = 0.0
            elif size > max_step:
                step *= max_step / size
            r = out
            np.subtract(out, step, out=out)
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            raise bad_call(err, q, xdot, out) from err
        if r is not out:  # pragma: no cover
            out[...] = r
        if not ddot(out, out) < _INF:
            return fallback("mda", J, xdot, out, q)
        return out

    return mda


# -- LNVA / JVJA in one compiled kernel -------------------------------------------------------


def compiled_step(ctrl: Workspace, jvja: int) -> Callable[..., np.ndarray]:
    """The LNVA (``jvja=0``) or single-joint JVJA (``jvja=1``) step of ``ctrl``, numba-compiled.

    Compiles :func:`step_kernel` on first use (here, not in the loop) and runs it once.
    """
    model, data, fid, rows = ctrl.model, ctrl.data, ctrl.frame_id, ctrl._rows
    n, m = ctrl.n, ctrl.m
    kernel = compiled_kernel()
    cfj, empty, ndarray, f64 = pin.computeFrameJacobian, np.empty, np.ndarray, np.float64
    G, B, c = np.empty((m, m)), np.empty((m, n)), np.empty(n)
    fw = ctrl._fw
    params = np.array([TRACE_MAX, ctrl._pivot_threshold, ctrl._rank_coef, ctrl._alpha])
    tolerate = ctrl.tolerate
    shape_n, shape_m = (n,), (m,)
    fallback, bad_call = ctrl._fallback, ctrl._bad_call
    check_tolerable = ctrl.scenarios.check_tolerable
    name = "jvja" if jvja else "lnva"
    if jvja:  # N = I - YᵀY with Y = L⁻¹J in B, for the bounded step's box check (boxstep)
        ctrl._jvja_ws[0], ctrl._jvja_ws[1], ctrl._jvja_ws[2] = B, B, c
    kernel(np.zeros((m, n)), np.zeros(m), np.zeros(n), G, B, c, fw, params, jvja)  # compile

    def slow(q, xdot, out, err: Exception) -> np.ndarray:
        """A call the compiled kernel refused (types, shapes): convert ``xdot`` once, or say why."""
        if type(out) is ndarray and out.shape == shape_n and out.dtype == f64:
            if not (type(xdot) is ndarray and xdot.dtype == f64):
                x2 = np.asarray(xdot, dtype=float)
                if x2.shape == shape_m:
                    return step(q, np.ascontiguousarray(x2), out)
        raise bad_call(err, q, xdot, out) from err

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        if out is None:
            out = empty(n)
        if type(out) is not ndarray or type(xdot) is not ndarray or out.dtype is not F64:
            return slow(q, xdot, out, TypeError("not a float64 array"))  # numba would compile it
        if xdot.dtype is not F64:
            return slow(q, xdot, out, TypeError("not a float64 array"))
        try:  # the kernel checks the sizes (status 3); numba checks the dtypes (TypeError)
            status = kernel(
                cfj(model, data, q, fid, _LWA)[rows], xdot, out, G, B, c, fw, params, jvja
            )
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            return slow(q, xdot, out, err)
        if status:
            if status == 3:
                return slow(q, xdot, out, ValueError("shape"))
            J = cfj(model, data, q, fid, _LWA)[rows]
            if status == 2 and not tolerate:
                check_tolerable(projection(J).N)  # raises IntolerableFailure naming the joint
            return fallback(name, J, xdot, out)
        return out

    step.__name__ = name
    step.__doc__ = (
        "JVJA, minimum square-sum jump rates, eq. (5) in closed form (G2); compiled."
        if jvja
        else "LNVA, least-norm rates ``q̇ = J⁺ẋ``; compiled."
    )
    return step
