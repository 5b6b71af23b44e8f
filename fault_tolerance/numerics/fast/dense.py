"""The small dense factorisations the compiled kernels share (numba, scalar loops).

One copy of each: the Controller's steps (:mod:`fault_tolerance.control.fast.step`,
:mod:`~fault_tolerance.control.fast.multi_step`, :mod:`~fault_tolerance.control.fast.mda_step`), the
compiled bounded step (:mod:`fault_tolerance.resolution.fast.box_basis`) and the simulated sample
(:mod:`fault_tolerance.numerics.fast.sample_dense`, :mod:`fault_tolerance.simulation.fast.sample`)
call these. ``G = J Jᵀ = L Lᵀ`` is kept in the lower triangle, the factor overwrites it in place.
"""

from __future__ import annotations

import math

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit


@njit
def cholesky(A, k) -> bool:  # pragma: no cover - numba
    """Lower Cholesky factor of ``A[:k, :k]`` (its lower triangle) in place; False unless PD."""
    for j in range(k):
        s = A[j, j]
        for t in range(j):
            s -= A[j, t] * A[j, t]
        if not s > 0.0:
            return False
        s = math.sqrt(s)
        A[j, j] = s
        for i in range(j + 1, k):
            u = A[i, j]
            for t in range(j):
                u -= A[i, t] * A[j, t]
            A[i, j] = u / s
    return True


@njit
def cholesky_into(G, L, m) -> bool:  # pragma: no cover - numba
    """Lower Cholesky factor of ``G[:m, :m]`` into ``L`` (``G`` kept); False unless PD."""
    for i in range(m):
        for j in range(i + 1):
            L[i, j] = G[i, j]
    return cholesky(L, m)


@njit
def gram_into(J, G) -> None:  # pragma: no cover - numba
    """``G = J Jᵀ`` into the lower triangle of ``G``."""
    m, n = J.shape
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += J[i, k] * J[j, k]
            G[i, j] = s


@_inline_once
def gram_factor(J, G) -> bool:  # pragma: no cover - numba
    """``G = J Jᵀ`` (lower triangle) and its Cholesky factor ``L``, in place; False unless PD."""
    gram_into(J, G)
    return cholesky(G, J.shape[0])


@_inline_once
def trace_inverse(L, z, m) -> float:  # pragma: no cover - numba
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


@njit
def forward(L, b, y, m) -> None:  # pragma: no cover - numba
    """``y = L⁻¹ b`` (``y`` may be ``b``)."""
    for i in range(m):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * y[k]
        y[i] = t / L[i, i]


@njit
def least_norm(J, xdot, L, Y, z, out) -> None:  # pragma: no cover - numba
    """``Y = L⁻¹ J``, ``z = L⁻¹ ẋ``, ``out = a = Yᵀ z = J⁺ẋ`` (``J Jᵀ = L Lᵀ``), row by row of ``Y``.

    Row ``i`` of ``Y`` is ``(J_i − Σ_{k<i} L_ik Y_k) / L_ii``, ``a`` gains ``z_i Y_i``: every
    inner loop runs along a row (the Jacobian comes in C order), so numba vectorises it, and each
    entry sees the same operations in the same order as one forward substitution per column.
    """
    m, n = J.shape
    forward(L, xdot, z, m)
    for col in range(n):
        out[col] = 0.0
    for i in range(m):
        for col in range(n):
            Y[i, col] = J[i, col]
        for k in range(i):
            lik = L[i, k]
            for col in range(n):
                Y[i, col] -= lik * Y[k, col]
        lii, zi = L[i, i], z[i]
        for col in range(n):
            y = Y[i, col] / lii
            Y[i, col] = y
            out[col] += y * zi


@njit
def null_apply(Y, c, u, n) -> None:  # pragma: no cover - numba
    """``c ← N c = c − Yᵀ(Y c)`` with ``N = I − YᵀY`` (``Y`` m x n, C order), ``u`` (m) scratch.

    ``u = Y c`` two rows per sweep of ``c`` (two independent sums, each in column order), then
    ``c`` loses ``u_r Y_r`` row by row (vectorised): for every entry the same operations in the
    same order as ``c_i − Σ_r Y_ri u_r``.
    """
    m = Y.shape[0]
    r = 0
    while r + 1 < m:
        s, t = 0.0, 0.0
        for i in range(n):
            s += Y[r, i] * c[i]
            t += Y[r + 1, i] * c[i]
        u[r], u[r + 1] = s, t
        r += 2
    if r < m:
        s = 0.0
        for i in range(n):
            s += Y[r, i] * c[i]
        u[r] = s
    for r in range(m):
        ur = u[r]
        for i in range(n):
            c[i] -= Y[r, i] * ur


@njit
def rank_ok(J, tr, coef) -> bool:  # pragma: no cover - numba
    """The rank certificate ``coef ‖J‖_F² trace(G⁻¹) < 1`` (always met when ``coef <= 0``)."""
    if not coef > 0.0:
        return True
    m, n = J.shape
    s = 0.0
    for i in range(m):
        for k in range(n):
            s += J[i, k] * J[i, k]
    return coef * s * tr < 1.0


@_inline_once
def chol_solve(L, k, b) -> None:  # pragma: no cover - numba
    """``b ← (L Lᵀ)⁻¹ b`` for the factor of :func:`cholesky`."""
    for i in range(k):
        t = b[i]
        for j in range(i):
            t -= L[i, j] * b[j]
        b[i] = t / L[i, i]
    for i in range(k - 1, -1, -1):
        t = b[i]
        for j in range(i + 1, k):
            t -= L[j, i] * b[j]
        b[i] = t / L[i, i]


@njit
def lu_solve(A, k, b) -> bool:  # pragma: no cover - numba
    """``b ← A[:k, :k]⁻¹ b`` by Gaussian elimination with partial pivoting (``A`` overwritten).

    False when a pivot is zero (``A`` singular).
    """
    for c in range(k):
        p, big = c, abs(A[c, c])
        for i in range(c + 1, k):
            if abs(A[i, c]) > big:
                p, big = i, abs(A[i, c])
        if not big > 0.0:
            return False
        if p != c:
            for j in range(k):
                A[c, j], A[p, j] = A[p, j], A[c, j]
            b[c], b[p] = b[p], b[c]
        for i in range(c + 1, k):
            f = A[i, c] / A[c, c]
            for j in range(c + 1, k):
                A[i, j] -= f * A[c, j]
            b[i] -= f * b[c]
    for i in range(k - 1, -1, -1):
        t = b[i]
        for j in range(i + 1, k):
            t -= A[i, j] * b[j]
        b[i] = t / A[i, i]
    return True


@njit
def chol_rank_one(L, m, x, sign) -> bool:  # pragma: no cover - numba
    """``L Lᵀ ± x xᵀ`` refactored in place (``sign`` +1.0 or −1.0) in ``O(m²)``; ``x`` destroyed.

    False when a downdate leaves the matrix not positive definite (``L`` then undefined).
    """
    for k in range(m):
        d = L[k, k] * L[k, k] + sign * x[k] * x[k]
        if not d > 0.0:
            return False
        r = math.sqrt(d)
        c, s = r / L[k, k], x[k] / L[k, k]
        L[k, k] = r
        for i in range(k + 1, m):
            L[i, k] = (L[i, k] + sign * s * x[i]) / c
            x[i] = c * x[i] - s * L[i, k]
    return True
