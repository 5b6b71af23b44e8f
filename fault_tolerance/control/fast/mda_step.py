"""The MDA step in one compiled kernel (numba backend): ``q̇ = J⁺ẋ − α N ∇K`` after the Jacobian.

:func:`mda_kernel` takes the 6-row ``LOCAL_WORLD_ALIGNED`` frame Jacobian ``Jf`` of one
``pin.computeFrameJacobian`` call and does the rest as scalar loops:

* the certificate and the least-norm rates as the LNVA / JVJA step (:mod:`.step`): one Cholesky
  factor of ``G = J Jᵀ``, ``trace(G⁻¹) ≤ TRACE_MAX``, ``Y = L⁻¹J``, ``a = Yᵀ(L⁻¹ẋ)``;
* ``∇K`` (:func:`rcn_gradient_kernel`, eq. 15 and its gradient): ``G = V diag(d) Vᵀ`` once and
  ``Z = VᵀJ``; each scenario's ``W_S = G − J_i J_iᵀ`` by its secular equation (the extreme
  eigenvalues, :mod:`fault_tolerance.numerics.fast.rank_one_eigen`), the eigenvectors in that
  basis in closed form ``y ∝ (diag(d) − μ)⁻¹ z`` (eq. K3; inverse iteration on ``W_S − μ I`` when
  the residual refuses one); ``∂λ/∂q_j = 2 ũᵀ (∂J/∂q_j) J_Sᵀ u`` summed over all the vectors
  through one ``m × m`` matrix (eq. K4), rotated back and contracted with the kinematic Hessian
  once, never formed (eq. K2, ``O(n)``);
* the singular reduced robots (``σ_min ≤ σ_max / RCN_SINGULAR``) add nothing (eq. S1), as in the
  reference :func:`fault_tolerance.resolution.indices.rcn_gradient`;
* the null step ``α N ∇K = α(∇K − Yᵀ(Y ∇K))``, capped at ``max_step`` as
  :func:`fault_tolerance.resolution.mda.mda` caps it.

Single-joint scenarios only (the Controller takes :func:`~fault_tolerance.control.lapack_steps.lapack_mda`
for multi-joint ones). Plain Python without numba (valid, and tested so: ``.py_func``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import pinocchio as pin

from fault_tolerance.control.fallback import fallback as _fallback
from fault_tolerance.control.lapack_steps import _LWA, _STEP_ERRORS, TRACE_MAX
from fault_tolerance.control.workspace import ControllerWorkspace
from fault_tolerance.errors import FaultToleranceError
from fault_tolerance.fast_cache import inline as _inline
from fault_tolerance.numerics.fast.dense import (
    cholesky_into,
    gram_into,
    least_norm,
    null_apply,
    rank_ok,
    trace_inverse,
)
from fault_tolerance.numerics.fast.rank_one_eigen import LANE_ROWS, all_extremes, eigenpairs
from fault_tolerance.numerics.fast.small_eigen import njit
from fault_tolerance.resolution.indices import RCN_MAX, RCN_SINGULAR

__all__ = [
    "compiled_mda_step",
    "gradient_kernel",
    "gradient_view",
    "gradient_workspace",
    "mda_kernel",
    "rcn_gradient_kernel",
]

_INF = math.inf
_EPS = 2.220446049250313e-16
#: A closed-form eigenvector (eq. K3) is kept when its residual is below this many ``m ε λ_max``.
RESIDUAL_TOL = 8.0
#: Entries of the parameter block (the first of the float workspace).
P_TRACE, P_RANK, P_GAIN, P_MAXSTEP, P_RCN_MAX, P_SINGULAR = range(6)
N_PARAMS = 6
#: Statuses: done; no certificate of ``σ_min(J) ≥ SIGMA_EPS`` (the planner's damped step); the
#: eigen solver gave up (the NumPy step); wrong sizes.
OK, UNCERTIFIED, NO_EIGEN, BAD_SIZE = 0, 1, 2, 3


@njit
def _triple(a0, a1, a2, b0, b1, b2, c0, c1, c2) -> float:  # pragma: no cover - numba
    """``c · (a × b)``."""
    return c0 * (a1 * b2 - a2 * b1) + c1 * (a2 * b0 - a0 * b2) + c2 * (a0 * b1 - a1 * b0)


# Eqn. (K1): ∂J_k/∂q_j = [ω_j × a_k; ω_j × ω_k] (j < k), [ω_k × a_j; 0] (j ≥ k), LWA columns.
@njit
def hessian_contract(Jf, ut, x, S, D) -> None:  # pragma: no cover - numba
    r"""``D_j = ũᵀ (∂J/∂q_j) x`` for every joint j, the Hessian never formed (eq. K1).

    ``Jf`` (6, n) the ``LOCAL_WORLD_ALIGNED`` Jacobian, columns ``[a_k; ω_k]``; ``ũ`` (6) a
    row-space vector (zero off the task rows). With the suffix sums :math:`A_j = \sum_{k>j} x_k
    a_k`, :math:`\Omega_j = \sum_{k>j} x_k \omega_k` and the prefix :math:`P_j = \sum_{k\le j} x_k
    \omega_k`: :math:`D_j = \tilde u_{lin}\cdot(\omega_j \times A_j + P_j \times a_j) + \tilde
    u_{ang}\cdot(\omega_j \times \Omega_j)`. ``S`` (n, 6) scratch.
    """
    n = Jf.shape[1]
    for r in range(6):
        S[n - 1, r] = 0.0
    for j in range(n - 2, -1, -1):
        xk = x[j + 1]
        for r in range(6):
            S[j, r] = S[j + 1, r] + xk * Jf[r, j + 1]
    p0, p1, p2 = 0.0, 0.0, 0.0
    for j in range(n):
        xj = x[j]
        w0, w1, w2 = Jf[3, j], Jf[4, j], Jf[5, j]
        p0 += xj * w0
        p1 += xj * w1
        p2 += xj * w2
        t = _triple(w0, w1, w2, S[j, 0], S[j, 1], S[j, 2], ut[0], ut[1], ut[2])
        t += _triple(p0, p1, p2, Jf[0, j], Jf[1, j], Jf[2, j], ut[0], ut[1], ut[2])
        t += _triple(w0, w1, w2, S[j, 3], S[j, 4], S[j, 5], ut[3], ut[4], ut[5])
        D[j] = t


@njit
def _lu_factor(W, mu, M, perm, m) -> None:  # pragma: no cover - numba
    """``P (W − μ I) = L U`` in ``M`` (partial pivoting, the row order in ``perm``).

    A zero pivot (the shift is an exact eigenvalue) is replaced by ``ε ‖W‖``: inverse iteration.
    """
    scale = 0.0
    for i in range(m):
        perm[i] = i
        for j in range(m):
            M[i, j] = W[i, j] - (mu if i == j else 0.0)
            scale = max(scale, abs(W[i, j]))
    tiny = _EPS * max(scale, 1e-300)
    for c in range(m):
        p = c
        for r in range(c + 1, m):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if p != c:
            for j in range(m):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            perm[c], perm[p] = perm[p], perm[c]
        if abs(M[c, c]) < tiny:
            M[c, c] = tiny
        for r in range(c + 1, m):
            f = M[r, c] / M[c, c]
            M[r, c] = f
            for j in range(c + 1, m):
                M[r, j] -= f * M[c, j]


@njit
def _lu_apply(M, perm, b, t, m) -> None:  # pragma: no cover - numba
    """``b ← (W − μ I)⁻¹ b`` with the factors of :func:`_lu_factor` (``t`` scratch)."""
    for i in range(m):
        t[i] = b[int(perm[i])]
    for i in range(m):
        s = t[i]
        for j in range(i):
            s -= M[i, j] * t[j]
        t[i] = s
    for i in range(m - 1, -1, -1):
        s = t[i]
        for j in range(i + 1, m):
            s -= M[i, j] * t[j]
        t[i] = s / M[i, i]
    for i in range(m):
        b[i] = t[i]


@njit
def _unit(u, m) -> bool:  # pragma: no cover - numba
    """``u ← u / ‖u‖``; False when ``u`` is zero or not finite."""
    s = 0.0
    for i in range(m):
        s += u[i] * u[i]
    if not (s > 0.0 and s < _INF):
        return False
    s = 1.0 / math.sqrt(s)
    for i in range(m):
        u[i] *= s
    return True


@njit
def _eigenvector(W, Vt, d, z, mu, top, u, y, M, m) -> bool:  # pragma: no cover - numba
    """Unit eigenvector of ``W = G − J_i J_iᵀ`` for its extreme eigenvalue ``μ`` into ``u``.

    Start ``u ∝ Vtᵀ (diag(d) − μ)⁻¹ z`` (``z = Vt J_i``; each distance at least ``ε d_m``, the
    eigenvector of ``d``'s end when nothing is left), then two steps of inverse iteration on
    ``W − μ I`` (one factorisation): exact also where ``J_i`` is (nearly) zero and ``W = G``.
    ``y`` holds ``2 m`` numbers.
    """
    if not _secular_start(d, z, mu, y, m):
        for k in range(m):
            y[k] = 0.0
        y[m - 1 if top else 0] = 1.0
    for r in range(m):
        u[r] = 0.0
    for k in range(m):
        yk = y[k]
        for r in range(m):
            u[r] += Vt[k, r] * yk
    perm, t = y[0:m], y[m : 2 * m]
    _lu_factor(W, mu, M, perm, m)
    for _ in range(2):
        _lu_apply(M, perm, u, t, m)
        if not _unit(u, m):
            return False
    return True


# Eqn. (K2): ∇_j = ω_j · Σ_{k>j} c_k + a_j · Σ_{k≤j} e_k, c_k = a_k × M_lin,k + ω_k × M_ang,k,
# e_k = M_lin,k × ω_k: all the vectors' contractions (K1) at once, from M = Σ_t c_t ũ_t x_tᵀ.
@njit
def matrix_contract(Jf, M, grad) -> None:  # pragma: no cover - numba
    r"""``grad_j = Σ_{r,k} M[r, k] (∂J/∂q_j)[r, k]`` for every joint j (eq. K2), ``O(n)``.

    ``M`` (6, n), zero off the task rows; the Hessian never formed. With ``M = ũ xᵀ`` this is
    :func:`hessian_contract`; a sum of such terms is contracted in one pass.
    """
    n = Jf.shape[1]
    s0, s1, s2 = 0.0, 0.0, 0.0  # Σ_{k>j} c_k, built from the end
    for j in range(n - 1, -1, -1):
        grad[j] = Jf[3, j] * s0 + Jf[4, j] * s1 + Jf[5, j] * s2
        a0, a1, a2, w0, w1, w2 = Jf[0, j], Jf[1, j], Jf[2, j], Jf[3, j], Jf[4, j], Jf[5, j]
        l0, l1, l2, g0, g1, g2 = M[0, j], M[1, j], M[2, j], M[3, j], M[4, j], M[5, j]
        s0 += a1 * l2 - a2 * l1 + w1 * g2 - w2 * g1
        s1 += a2 * l0 - a0 * l2 + w2 * g0 - w0 * g2
        s2 += a0 * l1 - a1 * l0 + w0 * g1 - w1 * g0
    p0, p1, p2 = 0.0, 0.0, 0.0  # Σ_{k≤j} e_k
    for j in range(n):
        l0, l1, l2, w0, w1, w2 = M[0, j], M[1, j], M[2, j], Jf[3, j], Jf[4, j], Jf[5, j]
        p0 += l1 * w2 - l2 * w1
        p1 += l2 * w0 - l0 * w2
        p2 += l0 * w1 - l1 * w0
        grad[j] += Jf[0, j] * p0 + Jf[1, j] * p1 + Jf[2, j] * p2


# Eqn. (K3): y = (diag(d) − μ)⁻¹ z / ‖·‖ (u = V y), kept when ‖(diag(d) − z zᵀ − μ) y‖ ≤ 8 m ε d_m.
@njit
def _secular_start(d, z, mu, y, m) -> bool:  # pragma: no cover - numba
    """``y = (diag(d) − μ)⁻¹ z`` normalised (eq. K3), each distance at least ``ε d_m``.

    False when nothing is left to normalise (``z`` zero where ``μ`` is not a pole).
    """
    tiny = _EPS * max(abs(d[m - 1]), 1e-300)
    for k in range(m):
        den = d[k] - mu
        if abs(den) < tiny:
            den = tiny if den >= 0.0 else -tiny
        y[k] = z[k] / den
    return _unit(y, m)


@njit
def _secular_vector(d, z, mu, y, m) -> bool:  # pragma: no cover - numba
    """The closed-form unit eigenvector of ``diag(d) − z zᵀ`` for ``μ`` (eq. K3) into ``y``.

    ``y`` is ``Vᵀu`` of the eigenvector ``u`` of ``W_S = G − J_i J_iᵀ`` (``z = Vᵀ J_i``). True
    when its residual in that basis is at rounding level (then ``u`` is as accurate as a
    backward-stable solver's); False sends the caller to :func:`_eigenvector`.
    """
    if not _secular_start(d, z, mu, y, m):
        return False
    zy = 0.0
    for k in range(m):
        zy += z[k] * y[k]
    res = 0.0
    for k in range(m):
        r = (d[k] - mu) * y[k] - z[k] * zy
        res += r * r
    return math.sqrt(res) <= RESIDUAL_TOL * m * _EPS * max(abs(d[m - 1]), 1e-300)


# Eqn. (K4): Σ_t c_t y_t (J_Sᵀu_t)ᵀ = B Z − Σ_t c_t (zᵀy_t) y_t e_iᵀ, B = Σ_t c_t y_t y_tᵀ.
@njit
def _gather(y, zy, coef, i, B, Me, m) -> None:  # pragma: no cover - numba
    """``B += coef · y yᵀ`` and ``Me[:, i] −= coef (zᵀy) y``: one vector's term of eq. (K4).

    In the eigenbasis of ``G`` (``y = Vᵀu``, ``z = Vᵀ J_i``) the term ``coef · y wᵀ`` of the
    vector ``w = J_Sᵀu = Zᵀy − (zᵀy) e_i`` (column ``i`` locked) splits into ``coef · y yᵀ Z``,
    summed over every vector first and multiplied by ``Z`` once (:func:`rcn_gradient_kernel`),
    and a correction of column ``i``.
    """
    for r in range(m):
        cy = coef * y[r]
        for c in range(m):
            B[r, c] += cy * y[c]
        Me[r, i] -= cy * zy


@njit
def _dot(a, b, m) -> float:  # pragma: no cover - numba
    """``aᵀb`` of the first ``m`` entries."""
    t = 0.0
    for k in range(m):
        t += a[k] * b[k]
    return t


@njit
def _refine(G, J, Vt, d, z, W, M, mu, top, i, out, y) -> bool:  # pragma: no cover - numba
    """``out = Vt u``, ``u`` the unit eigenvector of ``W_S`` for ``μ`` by inverse iteration.

    For the vectors whose closed form (eq. K3) was refused. ``W`` and ``M`` (m, m) scratch;
    ``y`` 3 m numbers.
    """
    m = J.shape[0]
    for r in range(m):
        for c in range(m):
            W[r, c] = (G[r, c] if c <= r else G[c, r]) - J[r, i] * J[c, i]
    u = y[2 * m : 3 * m]
    if not _eigenvector(W, Vt, d, z, mu, top, u, y, M, m):
        return False
    for k in range(m):  # back to the eigenbasis: Vt u
        out[k] = _dot(Vt[k], u, m)
    return True


@njit
def rcn_gradient_kernel(Jf, J, G, cols, params, F, grad) -> int:  # pragma: no cover - numba
    r"""``∇K``, ``K = Σ_S k_S²`` over the single-joint scenarios ``cols`` (eq. 15), into ``grad``.

    ``J`` (m, n) the task rows of ``Jf``, ``G = J Jᵀ`` (lower triangle read). Per scenario
    :math:`\partial(k^2)/\partial q_j = 2k(\sigma'_{max}\sigma_{min} -
    \sigma_{max}\sigma'_{min})/\sigma_{min}^2` with ``σ_min`` floored at ``σ_max / RCN_MAX`` and
    ``σ' = uᵀ(∂J_S/∂q_j)J_Sᵀu / σ``; singular reduced robots add nothing (eq. S1). Everything
    per scenario is done in the eigenbasis of ``G`` (``Z = Vt J`` once; eq. K3); the vectors of
    all scenarios are summed into one matrix, rotated back and contracted with the Hessian once
    (K2). ``F`` scratch of :func:`gradient_scratch` numbers. Returns :data:`OK` or
    :data:`NO_EIGEN`.
    """
    m, n = J.shape
    Vt, A = F[0 : m * m].reshape((m, m)), F[m * m : 2 * m * m].reshape((m, m))
    Mlu, W = F[2 * m * m : 3 * m * m].reshape((m, m)), F[3 * m * m : 4 * m * m].reshape((m, m))
    B = F[4 * m * m : 5 * m * m].reshape((m, m))
    o = 5 * m * m
    d, y = F[o : o + m], F[o + m : o + 4 * m]
    ymin, ymax, z = F[o + 4 * m : o + 5 * m], F[o + 5 * m : o + 6 * m], F[o + 6 * m : o + 7 * m]
    o += 7 * m
    work = F[o : o + 2 * m]
    o += 2 * m
    # One reshape for several matrices of a width (numba's reshape calls a helper, ~30 ns a
    # view); row slices of it are C-ordered views at no cost.
    R = F[o : o + (6 + 2 * m) * n].reshape((6 + 2 * m, n))
    M, Z, Me = R[0:6], R[6 : 6 + m], R[6 + m :]
    o += (6 + 2 * m) * n
    rix = cols[cols.shape[0] - m :]  # the task rows, after the scenarios' columns
    f = cols.shape[0] - m
    w = max(f, m)
    P = F[o : o + (m + 3) * f].reshape((m + 3, f))
    U2, E = P[0:m], P[m:]
    o += (m + 3) * f
    X = F[o : o + (LANE_ROWS + 1) * w].reshape((LANE_ROWS + 1, w))
    for c in range(n):
        grad[c] = 0.0
    if m < 2:
        return NO_EIGEN
    for r in range(m):
        for c in range(r + 1):
            A[r, c] = G[r, c]
    if not eigenpairs(A, m, Vt, d, work):
        return NO_EIGEN
    for k in range(m):  # Z = Vt J, Me = 0, B = 0
        for c in range(n):
            Z[k, c] = 0.0
            Me[k, c] = 0.0
        for c in range(m):
            B[k, c] = 0.0
        for r in range(m):
            v = Vt[k, r]
            for c in range(n):
                Z[k, c] += v * J[r, c]
    all_extremes(d, Z, cols[:f], m, U2, X, E)  # every scenario's secular roots, side by side
    for s in range(f):
        i = cols[s]
        lo, hi = E[0, s], E[1, s]
        if E[2, s] == 0.0:
            return NO_EIGEN
        for k in range(m):
            z[k] = Z[k, i]
        smax, sminr = math.sqrt(max(hi, 0.0)), math.sqrt(max(lo, 0.0))
        if not sminr > smax / params[P_SINGULAR]:  # a singular reduced robot: no term (eq. S1)
            continue
        if not _secular_vector(d, z, hi, ymax, m):  # eq. (K3), else inverse iteration
            if not _refine(G, J, Vt, d, z, W, Mlu, hi, True, i, ymax, y):
                return NO_EIGEN
        if not _secular_vector(d, z, lo, ymin, m):
            if not _refine(G, J, Vt, d, z, W, Mlu, lo, False, i, ymin, y):
                return NO_EIGEN
        smin = max(sminr, smax / params[P_RCN_MAX])
        k = smax / smin  # ‖J_Sᵀu‖ = σ: the vectors' terms divide by it (σ' above)
        _gather(ymax, _dot(z, ymax, m), 2.0 * k / (smin * smax), i, B, Me, m)
        _gather(ymin, _dot(z, ymin, m), -2.0 * k * smax / (smin * smin * sminr), i, B, Me, m)
    _rotate_back(Vt, B, Z, Me, rix, M)
    matrix_contract(Jf, M, grad)
    return OK


@njit
def _rotate_back(Vt, B, Z, Me, rix, M) -> None:  # pragma: no cover - numba
    """``M[rix] = Vtᵀ (B Z + Me)`` (the eigenbasis sum back on the task rows), zero elsewhere.

    ``Me`` is overwritten with ``B Z + Me``.
    """
    m, n = Me.shape
    for r in range(m):
        for k in range(m):
            b = B[r, k]
            for c in range(n):
                Me[r, c] += b * Z[k, c]
    for r in range(6):
        for c in range(n):
            M[r, c] = 0.0
    for k in range(m):
        for r in range(m):
            v, row = Vt[k, r], rix[r]
            for c in range(n):
                M[row, c] += v * Me[k, c]


@njit
def gradient_scratch(m, n, f):  # pragma: no cover - numba
    """Length of the scratch ``F`` of :func:`rcn_gradient_kernel` (``f`` scenarios)."""
    return 5 * m * m + 9 * m + 6 * n + 2 * m * n + (m + 3) * f + (LANE_ROWS + 1) * max(f, m)


@njit
def _task_gram(Jf, rix, J, G) -> None:  # pragma: no cover - numba
    """``J = Jf[rix]`` and ``G = J Jᵀ`` into the lower triangle of ``G``."""
    m, n = J.shape
    for r in range(m):
        for c in range(n):
            J[r, c] = Jf[rix[r], c]
    gram_into(J, G)


@njit
def gradient_kernel(Jf, F, Iw, m) -> int:  # pragma: no cover - numba
    """``∇K`` alone (the simulated sample's MDA): into ``F``'s gradient view (:func:`gradient_view`)."""
    n = Jf.shape[1]
    f = Iw.shape[0] - m
    if f < 1 or F.shape[0] != workspace_size(m, n, f) or Jf.shape[0] != 6:
        return BAD_SIZE
    o = N_PARAMS
    J = F[o : o + 2 * m * n].reshape((2 * m, n))[0:m]
    G = F[o + 2 * m * n : o + 2 * m * n + 2 * m * m].reshape((2 * m, m))[0:m]
    o += 2 * m * n + 2 * m * m + m
    _task_gram(Jf, Iw[f:], J, G)
    return rcn_gradient_kernel(Jf, J, G, Iw, F[0:N_PARAMS], F[o + n :], F[o : o + n])


def gradient_view(F: np.ndarray, m: int, n: int) -> np.ndarray:
    """The gradient ``∇K`` in the workspace ``F`` (written by both kernels), shape (n,)."""
    o = N_PARAMS + 2 * m * n + 2 * m * m + m
    return F[o : o + n]


# The MDA null step of eq. (15)'s gradient, capped as resolution.mda.mda caps it.
@_inline
def null_step(Y, a, out, grad, u, gain, max_step, n) -> None:  # pragma: no cover - numba
    """``out = a − s α N ∇K`` (``grad ← α N ∇K``, ``N = I − YᵀY``; ``out`` may be ``a``).

    ``s = min(1, max_step / ‖α N ∇K‖)``, 0 when that norm is not finite (no usable direction, as
    :func:`fault_tolerance.resolution.mda.mda`); ``u`` (m) scratch. Shared by :func:`mda_kernel`
    and the simulated sample (:mod:`fault_tolerance.simulation.fast.sample`).
    """
    null_apply(Y, grad, u, n)  # ∇K ← N ∇K
    size = 0.0
    for c in range(n):
        grad[c] *= gain
        size += grad[c] * grad[c]
    size = math.sqrt(size)
    scale = 1.0
    if not size < _INF:  # ∇K overflowed: no usable direction (as mda.mda)
        scale = 0.0
    elif size > max_step:
        scale = max_step / size
    for c in range(n):
        out[c] = a[c] - grad[c] * scale if scale != 0.0 else a[c]


@njit
def mda_kernel(Jf, xdot, out, F, Iw) -> int:  # pragma: no cover - numba
    """MDA rates ``a − α N ∇K`` (the step capped at ``max_step``) into ``out``; a status.

    ``Jf`` (6, n) the frame Jacobian (``LOCAL_WORLD_ALIGNED``); ``F`` the float workspace of
    :func:`gradient_workspace` (parameters ``P_*``, then ``J``, ``Y``, ``G``, ``L``, ``a``-side
    vectors and the gradient's scratch); ``Iw`` the scenarios' columns, then the task rows.
    """
    n = Jf.shape[1]
    m = xdot.shape[0]
    f = Iw.shape[0] - m
    if out.shape[0] != n or f < 1 or F.shape[0] != workspace_size(m, n, f) or Jf.shape[0] != 6:
        return BAD_SIZE
    params = F[0:N_PARAMS]
    o = N_PARAMS
    JY = F[o : o + 2 * m * n].reshape((2 * m, n))
    J, Y = JY[0:m], JY[m:]
    o += 2 * m * n
    GL = F[o : o + 2 * m * m].reshape((2 * m, m))
    G, L = GL[0:m], GL[m:]
    o += 2 * m * m
    zm, grad = F[o : o + m], F[o + m : o + m + n]
    o += m + n
    scratch = F[o:]
    _task_gram(Jf, Iw[f:], J, G)
    if not cholesky_into(G, L, m):
        return UNCERTIFIED
    tr = trace_inverse(L, zm, m)
    if not tr <= params[P_TRACE] or not rank_ok(J, tr, params[P_RANK]):
        return UNCERTIFIED
    least_norm(J, xdot, L, Y, zm, out)  # Y = L⁻¹J, a = Yᵀ(L⁻¹ẋ) in out
    status = rcn_gradient_kernel(Jf, J, G, Iw, params, scratch, grad)
    if status:
        return status
    null_step(Y, out, out, grad, zm, params[P_GAIN], params[P_MAXSTEP], n)
    s2 = 0.0
    for c in range(n):
        s2 += out[c] * out[c]
    return OK if s2 < _INF else UNCERTIFIED


@njit
def workspace_size(m, n, f):  # pragma: no cover - numba
    """Length of the float workspace of :func:`mda_kernel` (``f`` scenarios)."""
    return N_PARAMS + 2 * m * n + 2 * m * m + m + n + gradient_scratch(m, n, f)


def gradient_workspace(cw: ControllerWorkspace) -> tuple[np.ndarray, np.ndarray]:
    """``(F, Iw)`` of :func:`mda_kernel` for the Controller workspace ``cw`` (single-joint scenarios)."""
    m, n = cw.m, cw.n
    f = len(cw.scenarios.columns)
    F = np.zeros(getattr(workspace_size, "py_func", workspace_size)(m, n, f))
    F[:N_PARAMS] = TRACE_MAX, cw.rank_coef, cw.gain, cw.max_step, RCN_MAX, RCN_SINGULAR
    rows = np.arange(6)[cw.rows]
    Iw = np.concatenate([np.asarray(cw.scenarios.columns, dtype=np.int64), rows.astype(np.int64)])
    return F, np.ascontiguousarray(Iw)


def compiled_mda_step(
    cw: ControllerWorkspace, slow: Callable[..., np.ndarray]
) -> Callable[..., np.ndarray]:
    """The MDA step of ``cw``, numba-compiled; ``slow`` (the LAPACK/NumPy step) takes what it refuses.

    Compiles :func:`mda_kernel` on first use (here, not in the loop), then freezes the dispatcher.
    """
    model, data, fid, n = cw.model, cw.data, cw.frame_id, cw.n
    cfj, empty = pin.computeFrameJacobian, np.empty
    F, Iw = gradient_workspace(cw)
    fallback = partial(_fallback, cw)
    rows = cw.rows
    kernel = mda_kernel
    J0 = cfj(model, data, pin.neutral(model), fid, _LWA)
    kernel.disable_compile(False)
    kernel(J0, np.zeros(cw.m), np.zeros(n), F, Iw)
    kernel.disable_compile(True)

    def mda(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """MDA, maximum-dexterity rates ``q̇ = J⁺ẋ − α N ∇K``; compiled."""
        if out is None:
            out = empty(n)
        try:
            Jf = cfj(model, data, q, fid, _LWA)
            status = kernel(Jf, xdot, out, F, Iw)
        except FaultToleranceError:
            raise
        except _STEP_ERRORS:
            return slow(q, xdot, out)  # types or layouts the kernel was not compiled for
        if status == UNCERTIFIED:
            return fallback("mda", Jf[rows], xdot, out, q)
        if status:
            return slow(q, xdot, out)
        return out

    return mda
