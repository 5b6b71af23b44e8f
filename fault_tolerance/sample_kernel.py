"""One simulated sample after the Jacobian, in one compiled kernel: rates, λ parts, k_S, σ_min, flags.

:func:`sample_kernel` is what :func:`fault_tolerance.simulation.simulate` runs at every sample
(through :class:`fault_tolerance.sampler.Sampler`): from the task Jacobian ``J`` and the commanded
task velocity it computes, with one Cholesky factorisation of ``G = J Jᵀ`` and never the n x n
projector ``N`` itself (only its diagonal and its products with vectors, ``N v = v - Jᵀ(G⁻¹ J v)``):

* the rates: LNVA ``a = J⁺ẋ``; JVJA in closed form (G2) ``a - N c / W``; MDA ``a - α N ∇K``
  (``∇K`` given, the step capped as in :func:`fault_tolerance.planner.mda`); rates given by the
  caller; or, after a lock, the least-norm rates of the remaining joints;
* the jump each scenario would cause now, ``w_S ‖ˢq̇' − q̇‖²`` (eqs. 9/10; ``ˢq̇'`` by G1, least-norm or
  continuation response, G3);
* the reduced condition numbers ``k_S`` (eq. 15) from ``eigvalsh`` of ``J_S J_Sᵀ = G − J_i J_iᵀ``,
  their square sum ``K`` and ``σ_min(J)``;
* the flags of :mod:`fault_tolerance.run` it can decide (locked, step-limited, over-speed).

It returns -1 when the sample needs the reference code instead: no certificate that
``σ_min ≥ SIGMA_EPS`` (the reference damps there), a pivot ``N_ii`` below ``PIVOT_EPS`` (the
reference damps and flags it), or numbers that are not finite. Plain Python, valid without
numba (and tested so); compiled by :func:`compiled_sample_kernel`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

try:  # compiled when numba is there (lazily, on first call; cached on disk)
    import numba

    _njit = numba.njit(cache=True, nogil=True, error_model="numpy")
except ImportError:  # pragma: no cover - numba is a core dependency

    def _njit(fn):
        return fn


#: ``method`` codes of :func:`sample_kernel`.
LNVA, JVJA, MDA, GIVEN, LOCKED = 0, 1, 2, 3, 4
#: Indices into ``params``.
P_TRACE, P_PIVOT, P_RANK, P_WSUM, P_GAIN, P_MAXSTEP, P_RCN_MAX, P_CONT, P_LOCK = range(9)
P_DT, P_DECAY, P_ACCEL = 9, 10, 11
N_PARAMS = 12
#: Indices into ``off``, the first column of each history in the run table (``simulation``).
COLUMNS = ("q", "qd", "qd_cmd", "x", "x_des", "error", "jvj", "jvj_parts", "rcn", "K",
           "sigma_min", "flags")  # fmt: skip
O_Q, O_QD, O_QCMD, O_X, O_XDES, O_ERROR, O_JVJ, O_PARTS, O_RCN, O_K, O_SIGMA, O_FLAGS = range(12)

_FLAG_LOCKED, _FLAG_STEP_LIMITED, _FLAG_OVER_SPEED = 4, 8, 16


@_njit
def _cholesky(G, L, m) -> bool:  # pragma: no cover - numba
    """Lower Cholesky factor of the leading m x m block of G into L; False unless G is PD."""
    for j in range(m):
        s = G[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        s = math.sqrt(s)
        L[j, j] = s
        for i in range(j + 1, m):
            t = G[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / s
    return True


@_njit
def _trace_inverse(L, z, m) -> float:  # pragma: no cover - numba
    """``trace(G⁻¹) = ‖L⁻¹‖_F²``, column by column of ``L⁻¹`` (``z`` as scratch)."""
    tr = 0.0
    for j in range(m):
        for i in range(j, m):
            t = 1.0 if i == j else 0.0
            for k in range(j, i):
                t -= L[i, k] * z[k]
            z[i] = t / L[i, i]
            tr += z[i] * z[i]
    return tr


@_njit
def _solve(L, b, y, m) -> None:  # pragma: no cover - numba
    """``y = G⁻¹ b`` with ``G = L Lᵀ`` (``y`` may be ``b``)."""
    for i in range(m):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * y[k]
        y[i] = t / L[i, i]
    for i in range(m - 1, -1, -1):
        t = y[i]
        for k in range(i + 1, m):
            t -= L[k, i] * y[k]
        y[i] = t / L[i, i]


@_njit
def _null_times(J, B, v, out, y) -> None:  # pragma: no cover - numba
    """``out = N v = v - Jᵀ (B v)``, ``B = G⁻¹J``: O(mn), N never formed."""
    m, n = J.shape
    for i in range(m):
        s = 0.0
        for j in range(n):
            s += B[i, j] * v[j]
        y[i] = s
    for j in range(n):
        s = v[j]
        for i in range(m):
            s -= J[i, j] * y[i]
        out[j] = s


@_njit
def _condition(G, J, cols, ks, W, rcn_max) -> float:  # pragma: no cover - numba
    """``k_S`` of every single-joint scenario into ``ks``, as ``indices.condition_numbers``; K."""
    m = G.shape[0]
    K = 0.0
    for s in range(cols.shape[0]):
        i = cols[s]
        for r in range(m):
            for c in range(m):
                W[r, c] = G[r, c] - J[r, i] * J[c, i]
        lam = np.linalg.eigvalsh(W)
        smax = math.sqrt(max(lam[m - 1], 0.0))
        smin = max(math.sqrt(max(lam[0], 0.0)), smax / rcn_max)
        k = smax / smin if smax > 0.0 else rcn_max  # smin >= smax / rcn_max > 0 then
        k = min(k, rcn_max)
        ks[s] = k
        K += k * k
    return K


@_njit
def _factor(J, xd, cols, params, G, L, B, a, piv, y, z) -> bool:  # pragma: no cover - numba
    """Cholesky of ``G = J Jᵀ`` with its certificate, ``B = G⁻¹J``, ``a = J⁺ẋ``, pivots ``N_ii``.

    False when the reference must do the sample (no certificate, or a pivot below PIVOT_EPS).
    """
    m, n = J.shape
    if not _cholesky(G, L, m):
        return False
    tr = _trace_inverse(L, z, m)
    if not tr <= params[P_TRACE]:
        return False
    if params[P_RANK] > 0.0:
        s = 0.0
        for i in range(m):
            for c in range(n):
                s += J[i, c] * J[i, c]
        if not params[P_RANK] * s * tr < 1.0:
            return False
    for c in range(n):  # B = G⁻¹ J column by column
        for i in range(m):
            y[i] = J[i, c]
        _solve(L, y, y, m)
        for i in range(m):
            B[i, c] = y[i]
    for c in range(n):
        s = 0.0
        for i in range(m):
            s += B[i, c] * xd[i]
        a[c] = s
    for k in range(cols.shape[0]):  # pivots N_ii = 1 - J_iᵀ B_i of the lockable columns
        i = cols[k]
        d = 1.0
        for r in range(m):
            d -= J[r, i] * B[r, i]
        if not d >= params[P_PIVOT]:
            return False
        piv[k] = d
    return True


@_njit
def _planned(
    J, B, a, piv, cols, w, params, method, qd_in, grad, qd, v, Nv, y
) -> int:  # pragma: no cover - numba
    """The rates of ``method`` into ``qd``; returns FLAG_STEP_LIMITED or 0."""
    n = J.shape[1]
    if method == LNVA:
        for c in range(n):
            qd[c] = a[c]
    elif method == JVJA:  # (G2): a - N c / W, c_i = w_i a_i / N_ii
        for c in range(n):
            v[c] = 0.0
        for k in range(cols.shape[0]):
            v[cols[k]] += w[k] * a[cols[k]] / piv[k]
        _null_times(J, B, v, Nv, y)
        for c in range(n):
            qd[c] = a[c] - Nv[c] / params[P_WSUM]
    elif method == MDA:  # a - α N ∇K, the step capped at max_step (planner.mda)
        _null_times(J, B, grad, Nv, y)
        size = 0.0
        for c in range(n):
            Nv[c] *= params[P_GAIN]
            size += Nv[c] * Nv[c]
        size = math.sqrt(size)
        scale = 1.0
        if not size < math.inf:
            scale = 0.0
        elif size > params[P_MAXSTEP]:
            scale = params[P_MAXSTEP] / size
        t = 0.0
        for c in range(n):
            qd[c] = a[c] - Nv[c] * scale if scale != 0.0 else a[c]
            t += (qd[c] - a[c]) * (qd[c] - a[c])
        if math.sqrt(t) >= 0.999 * params[P_MAXSTEP]:
            return _FLAG_STEP_LIMITED
    else:
        for c in range(n):
            qd[c] = qd_in[c]
    return 0


@_njit
def _jumps(J, B, a, qd, piv, cols, w, cont, parts) -> float:  # pragma: no cover - numba
    """``w_S ‖ˢq̇' − q̇‖²`` of every scenario into ``parts`` (eqs. 9/10, G1/G3); their sum."""
    m, n = J.shape
    total = 0.0
    for k in range(cols.shape[0]):
        i = cols[k]
        t = (qd[i] if cont else a[i]) / piv[k]
        acc = 0.0
        for c in range(n):
            ncol = 1.0 if c == i else 0.0
            for r in range(m):
                ncol -= J[r, c] * B[r, i]
            post = 0.0 if c == i else (qd[c] if cont else a[c]) - t * ncol
            e = post - qd[c]
            acc += e * e
        parts[k] = w[k] * acc
        total += parts[k]
    return total


@_njit
def _locked(J, xd, G, params, Wm, L, y, z, qd) -> bool:  # pragma: no cover - numba
    """Least-norm rates of the joints left after the lock, ``G_r = G − J_l J_lᵀ``; False: reference."""
    m, n = J.shape
    lock = int(params[P_LOCK])
    for i in range(m):
        for j in range(m):
            Wm[i, j] = G[i, j] - J[i, lock] * J[j, lock]
    if not _cholesky(Wm, L, m) or not _trace_inverse(L, z, m) <= params[P_TRACE]:
        return False
    _solve(L, xd, y, m)
    for c in range(n):
        s = 0.0
        if c != lock:
            for i in range(m):
                s += J[i, c] * y[i]
        qd[c] = s
    return True


@_njit
def _follow(qd_cmd, qd_prev, params, k, locked, out) -> None:  # pragma: no cover - numba
    """Actual rates one step later, as ``simulation.ServoModel.follow`` (a locked joint stops)."""
    decay, step = params[P_DECAY], params[P_ACCEL]
    for c in range(qd_cmd.shape[0]):
        t = qd_cmd[c]
        if k > 0:
            if decay >= 0.0:
                t = qd_cmd[c] + (qd_prev[c] - qd_cmd[c]) * decay
            if step < math.inf:
                t = qd_prev[c] + min(max(t - qd_prev[c], -step), step)
        out[c] = t
    if locked:
        out[int(params[P_LOCK])] = 0.0


@_njit
def sample_kernel(
    J, xd, qd_in, grad, q, qd_prev, x, x_des, err, cols, w, vmax, params, method, k, T, off, ws
) -> int:  # pragma: no cover - numba
    """Sample ``k`` after the Jacobian into row ``k`` of the run table ``T``; the flags, or -1.

    ``J`` (m, n); ``xd`` the commanded task velocity; ``qd_in`` the rates for ``GIVEN``; ``grad``
    ``∇K`` for ``MDA``; ``q``, ``qd_prev`` the configuration and the actual rates so far (``q`` is
    advanced in place by ``q̇ dt``); ``x``, ``x_des``, ``err`` the task position, its target and
    error; ``cols`` the lockable column of each scenario, ``w`` their weights; ``vmax`` the joint
    velocity limits (inf: none); ``params`` see ``P_*``; ``method`` one of ``LNVA, JVJA, MDA,
    GIVEN, LOCKED``; ``T`` the run table and ``off`` its column offsets (``O_*``); ``ws`` a float
    workspace of :func:`workspace_size` numbers. -1: nothing usable was written; the caller does
    the sample the reference way.
    """
    m, n = J.shape
    f = cols.shape[0]
    G, L, Wm = (
        ws[0 : m * m].reshape((m, m)),
        ws[m * m : 2 * m * m].reshape((m, m)),
        ws[2 * m * m : 3 * m * m].reshape((m, m)),
    )
    o = 3 * m * m
    B = ws[o : o + m * n].reshape((m, n))
    o += m * n
    a, v, Nv, piv, qd = (
        ws[o : o + n],
        ws[o + n : o + 2 * n],
        ws[o + 2 * n : o + 3 * n],
        ws[o + 3 * n : o + 4 * n],
        ws[o + 4 * n : o + 5 * n],
    )
    o += 5 * n
    y, z = ws[o : o + m], ws[o + m : o + 2 * m]
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for c in range(n):
                s += J[i, c] * J[j, c]
            G[i, j] = s
            G[j, i] = s
    row = T[k]
    parts = row[off[O_PARTS] : off[O_PARTS] + f]
    flag = 0
    if method == LOCKED:
        if not _locked(J, xd, G, params, Wm, L, y, z, qd):
            return -1
        flag = _FLAG_LOCKED
        for i in range(f):
            parts[i] = 0.0
        jv = 0.0
    else:
        if not _factor(J, xd, cols, params, G, L, B, a, piv, y, z):
            return -1
        flag = _planned(J, B, a, piv, cols, w, params, method, qd_in, grad, qd, v, Nv, y)
        jv = _jumps(J, B, a, qd, piv, cols, w, params[P_CONT] > 0.0, parts)
    total = 0.0
    for c in range(n):
        total += qd[c] * qd[c]
        if abs(qd[c]) > vmax[c]:
            flag |= _FLAG_OVER_SPEED
    if not total < math.inf:
        return -1
    row[off[O_K]] = _condition(G, J, cols, row[off[O_RCN] : off[O_RCN] + f], Wm, params[P_RCN_MAX])
    lam = np.linalg.eigvalsh(G)
    row[off[O_SIGMA]] = math.sqrt(max(lam[0], 0.0))
    _follow(qd, qd_prev, params, k, method == LOCKED, row[off[O_QD] : off[O_QD] + n])
    e = 0.0
    for i in range(m):
        row[off[O_X] + i] = x[i]
        row[off[O_XDES] + i] = x_des[i]
        e += err[i] * err[i]
    for c in range(n):
        row[off[O_Q] + c] = q[c]
        row[off[O_QCMD] + c] = qd[c]
        q[c] += row[off[O_QD] + c] * params[P_DT]
    row[off[O_ERROR]] = math.sqrt(e)
    row[off[O_JVJ]] = jv
    row[off[O_FLAGS]] = flag
    return flag


def workspace_size(m: int, n: int) -> int:
    """Length of the float workspace ``ws`` of :func:`sample_kernel`."""
    return 3 * m * m + m * n + 5 * n + 2 * m


def compiled_sample_kernel() -> Callable:
    """:func:`sample_kernel` compiled by numba; ImportError without numba."""
    import numba  # noqa: F401 - raises ImportError here when numba is missing

    return sample_kernel
