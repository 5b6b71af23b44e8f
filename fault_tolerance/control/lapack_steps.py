"""Backend kernels of :class:`~fault_tolerance.control.controller.Controller`: each step, per backend.

* The LAPACK/BLAS-shaped calls of a step (``dsyrk``, ``dposv``, ``dtrtri``, ``dgemm``,
  ``dgemv``), done by NumPy (:func:`numpy_linalg`): the plain steps of the ``numpy`` backend,
  where numba is not installed (one plain implementation; scipy's wrappers, a second, went).
* :func:`step_kernel`: the whole LNVA / single-joint JVJA step after the Jacobian, as scalar
  loops; :func:`compiled_kernel`: that kernel compiled by numba (imported then; cached on disk).
* The step builders :func:`lapack_lnva`, :func:`lapack_jvja`, :func:`lapack_mda` and
  :func:`compiled_step`: each reads a Controller's
  :class:`~fault_tolerance.control.workspace.ControllerWorkspace` (scenario tables, thresholds,
  linear-algebra calls ``la``) and returns its ``step(q, xdot, out=None) -> qd`` closure.

Every step certifies ``σ_min(J) ≥ SIGMA_EPS`` by ``trace((J Jᵀ)⁻¹) ≤ TRACE_MAX``, or hands the
step to :func:`fault_tolerance.control.fallback.fallback` (the planner, damped): see :mod:`fault_tolerance.control.controller`.
Importing this module imports neither numba nor scipy.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from types import SimpleNamespace

import numpy as np
import pinocchio as pin

from fault_tolerance.control.fallback import bad_call as _bad_call
from fault_tolerance.control.fallback import fallback as _fallback
from fault_tolerance.control.workspace import ControllerWorkspace
from fault_tolerance.errors import FaultToleranceError
from fault_tolerance.numerics.linalg import RANK_RTOL, SIGMA_EPS, projection

__all__ = [
    "TRACE_MAX",
    "lapack_jvja",
    "lapack_lnva",
    "lapack_mda",
    "shift_general",
    "numpy_linalg",
]

#: ``trace((J Jᵀ)⁻¹)`` up to which ``σ_min(J) ≥ SIGMA_EPS`` is certain, so no damping is needed.
TRACE_MAX = 1.0 / SIGMA_EPS**2

_LWA = pin.LOCAL_WORLD_ALIGNED
_WORLD = pin.WORLD
_INF = float("inf")
_STEP_ERRORS = (ValueError, TypeError, RuntimeError, AttributeError, IndexError)
F64 = np.dtype(np.float64)


# -- the step's certificate: what the arm lets it skip ------------------------------------------


def _jacobian_norm2_bound(arm) -> float:
    """An upper bound of ``‖J‖_F²`` over all configurations, or inf when none is known.

    A revolute column has a unit angular part and a linear part no longer than the distance from
    its axis to the tip, itself below the sum of the joint and tip offsets.
    """
    model = arm.model
    kinds = [model.joints[j].shortname() for j in range(1, model.njoints)]
    if not all(k.startswith("JointModelR") for k in kinds):
        return _INF
    reach = sum(
        float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(1, model.njoints)
    )
    reach += float(np.linalg.norm(model.frames[arm.frame_id].placement.translation))
    return arm.n * (1.0 + reach**2)


def row_selector(arm) -> slice | np.ndarray:
    """Row selector of the 6-row frame Jacobian: a slice (a view, no copy) when it can be."""
    rows = np.asarray(arm.rows)
    if bool(np.all(np.diff(rows) == 1)):
        return slice(int(rows[0]), int(rows[0]) + len(rows))
    return rows


def rank_coefficient(arm) -> float:
    """Coefficient of the per-step rank test (0: not needed for this arm).

    With σ_min ≥ SIGMA_EPS certified, the rank test of linalg.projection (σ > RANK_RTOL σ_max) can
    fail only if ‖J‖_F² > SIGMA_EPS² / RANK_RTOL² (= 1e12): arms whose Jacobian is bounded far
    below that skip the per-step test.
    """
    bounded = _jacobian_norm2_bound(arm) * RANK_RTOL**2 * TRACE_MAX < 0.5
    return 0.0 if bounded else RANK_RTOL**2


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


# Eqn. (5) in closed form (G2), one step after the Jacobian; compiled by numba.
# -- LNVA / JVJA / MDA with LAPACK (or NumPy) calls --------------------------------------------


def lapack_lnva(ws: ControllerWorkspace) -> Callable[..., np.ndarray]:
    """The LNVA step of a Controller's workspace ``ws`` with its LAPACK (or NumPy) calls: ``lnva(q, xdot, out=None)``."""
    model, data, fid, rows = ws.model, ws.data, ws.frame_id, ws.rows
    n, m = ws.n, ws.m
    la = ws.la
    dsyrk, dposv, dtrtri, ddot = la.dsyrk, la.dposv, la.dtrtri, la.ddot
    cfj, dot, empty = pin.computeFrameJacobian, np.dot, np.empty
    GT = np.zeros((m, m), order="F")  # LAPACK works in its upper triangle; the rest stays 0
    fallback, bad_call = partial(_fallback, ws), partial(_bad_call, ws)

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


def lapack_jvja(ws: ControllerWorkspace) -> Callable[..., np.ndarray]:
    """The JVJA step of ``ws`` with its LAPACK (or NumPy) calls, any scenarios (G1, G2)."""
    model, data, fid, rows = ws.model, ws.data, ws.frame_id, ws.rows
    n, m = ws.n, ws.m
    la = ws.la
    dsyrk, dposv, dtrtri, ddot = la.dsyrk, la.dposv, la.dtrtri, la.ddot
    dgemv = la.dgemv
    cfj, dot, empty = pin.computeFrameJacobian, np.dot, np.empty
    divide, multiply, add, subtract, einsum = np.divide, np.multiply, np.add, np.subtract, np.einsum
    GT = np.zeros((m, m), order="F")
    c, d, dF = np.empty(n), np.empty(n), np.empty(n)
    off, wrel = ws.fw[0], ws.fw[1]
    rank_coef, alpha = ws.rank_coef, ws.alpha
    fallback, bad_call = partial(_fallback, ws), partial(_bad_call, ws)
    general = partial(shift_general, ws)
    tol, tolerate = ws.pivot_threshold, ws.tolerate
    check_tolerable = ws.scenarios.check_tolerable
    mode = ("all" if ws.all_uniform else "singletons") if ws.singletons else "general"
    weighted = not ws.uniform
    last = ws.jvja_factors
    last[2] = c

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
            last[0], last[1] = J, B  # N = I - JᵀB, for the bounded step's box check (boxstep)
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


def lapack_mda(ws: ControllerWorkspace, arm) -> Callable[..., np.ndarray]:
    """The MDA step of ``ws``: ``mda(q, xdot, out=None)``, the reference rates of ``arm`` at ``q``.

    MDA is the paper's comparison baseline: the step is the reference
    :func:`fault_tolerance.resolution.mda.mda` on the arm's Jacobian and its derivatives
    (:meth:`~fault_tolerance.model.arm.Arm.jacobian_derivatives`), so it equals
    ``ft.resolve("mda")`` to the last bit, also near reduced singularities, where the rates move
    by 1e-5 relative for a change of 1e-16 in ``∂J/∂q`` (measured on the spatial 4R at
    ``q₄ = 2e-3``); a few hundred µs a step.
    """
    from fault_tolerance.resolution.mda import mda as reference_mda

    n = ws.n
    bad_call = partial(_bad_call, ws)
    sc, gain, max_step = ws.scenarios, ws.gain, ws.max_step

    def mda(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """MDA, maximum-dexterity rates ``q̇ = J⁺ẋ - α N ∇K``."""
        if out is None:
            out = np.empty(n)
        try:
            J, dJ = arm.jacobian(q), arm.jacobian_derivatives(q)
            out[:] = reference_mda(J, xdot, sc, dJ=dJ, gain=gain, max_step=max_step)
        except FaultToleranceError:
            raise
        except _STEP_ERRORS as err:
            raise bad_call(err, q, xdot, out) from err
        return out

    return mda


# -- multi-joint JVJA (G1) --------------------------------------------------------------------
def shift_general(
    ws: ControllerWorkspace, J: np.ndarray, B: np.ndarray, a: np.ndarray, c: np.ndarray
) -> bool:
    """``c = Σ_S (w_S/W) E_S N[S,S]⁻¹ a[S]`` (G1), one batched solve per scenario size.

    ``N[S, S] = I - J_Sᵀ B_S`` (``B = G⁻¹J``): N itself is never formed. False when a pivot
    needs the planner's damping (``tolerate``); raises when intolerable.
    """
    c[:] = 0.0
    for idx, wrel in ws.groups:
        NSS = -np.einsum("rks,rkt->kst", J[:, idx], B[:, idx])  # (k, s, s)
        NSS[:, range(idx.shape[1]), range(idx.shape[1])] += 1.0
        if idx.shape[1] == 1:
            piv = NSS[:, 0, 0]
            if piv.min() < ws.pivot_threshold:
                if ws.tolerate:
                    return False
                ws.scenarios.check_tolerable(np.eye(ws.n) - J.T @ B)
            np.add.at(c, idx[:, 0], wrel * a[idx[:, 0]] / piv)
            continue
        if np.linalg.eigvalsh(NSS)[:, 0].min() < ws.pivot_threshold:
            if ws.tolerate:
                return False
            ws.scenarios.check_tolerable(np.eye(ws.n) - J.T @ B)
        sol = np.linalg.solve(NSS, a[idx][:, :, None])[:, :, 0]  # (k, s)
        np.add.at(c, idx.ravel(), (wrel[:, None] * sol).ravel())
    return True
