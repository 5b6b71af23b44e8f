"""Linear algebra of the compiled bounded step: the factor, null-space bases (L6), reduced rates.

Used by :mod:`fault_tolerance.control.fast.bounded_solve`: :func:`factor` (Cholesky of ``J Jᵀ``, ``J⁺ẋ``, the
certificates of the step kernel), :func:`null_basis` (Householder QR of ``Jᵀ``),
:func:`reduced_basis` (a reduced robot's basis from the task's by reflections),
:func:`reduced_rates` ((G1) from the basis), :func:`undamped` (whether and how much the
reference damps a reduced Jacobian) and :func:`damped_rates` (its damped least-norm rates then). Scalar loops in caller-given buffers; compiled by numba (plain Python
without it). See docs/MATH.md "Joint limits, compiled".
"""

from __future__ import annotations

import math

import numpy as np

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.numerics.fast.dense import gram_factor, least_norm, rank_ok, trace_inverse
from fault_tolerance.numerics.linalg import DAMPING, RANK_RTOL
from fault_tolerance.resolution.fast.box_qp import _chol_solve, _cholesky, _dot_rows, _njit


@_njit
def factor(J, xdot, L, Y, z, a, params):  # pragma: no cover - numba
    """``J Jᵀ = L Lᵀ``, ``Y = L⁻¹J``, ``a = Yᵀ L⁻¹ẋ = J⁺ẋ``; returns ``(status, trace(G⁻¹))``.

    Status 1 without the certificates of :func:`fault_tolerance.control.fast.step.step_kernel`
    (``trace(G⁻¹) = ‖L⁻¹‖_F² ≤ params[0]``, and the rank test when ``params[2] > 0``).
    """
    m, n = J.shape
    if not gram_factor(J, L):
        return 1, math.inf
    tr = trace_inverse(L, z, m)
    if not tr <= params[0]:
        return 1, tr
    if not rank_ok(J, tr, params[2]):
        return 1, tr
    least_norm(J, xdot, L, Y, z, a)
    return 0, tr


@_njit
def reduced_rates(Z, r, a, S, k, post, NSS, ys, thr, zr):  # pragma: no cover - numba
    """(G1) rates ``post`` of the reduced robot ``S = S[:k]`` (``N = Z Zᵀ``); ``tr(N[S,S]⁻¹)``.

    Returns −1 when ``N[S, S] − thr·I`` is not positive definite (a pivot below the threshold).
    ``zr`` (r,) is scratch.
    """
    n = a.shape[0]
    if k == 1:  # one joint: N_ii = ‖Z_i‖², post = a − (a_i / N_ii) Z Z_iᵀ
        i = S[0]
        piv = _dot_rows(Z, r, i, i)
        if not piv - thr > 0.0:
            return -1.0
        ratio = a[i] / piv
        for c in range(r):
            zr[c] = Z[i, c] * ratio
        for j in range(n):
            v = a[j]
            for c in range(r):
                v -= Z[j, c] * zr[c]
            post[j] = v
        post[i] = 0.0
        return 1.0 / piv
    for t in range(k):
        for u in range(t + 1):
            NSS[t, u] = _dot_rows(Z, r, S[t], S[u]) - (thr if t == u else 0.0)
    if not _cholesky(NSS, k):
        return -1.0
    for t in range(k):
        for u in range(t + 1):
            NSS[t, u] = _dot_rows(Z, r, S[t], S[u])
    _cholesky(NSS, k)
    for t in range(k):
        ys[t] = a[S[t]]
    _chol_solve(NSS, k, ys)
    for c in range(r):  # N[:, S] y = Z (Z_Sᵀ y)
        t2 = 0.0
        for t in range(k):
            t2 += Z[S[t], c] * ys[t]
        zr[c] = t2
    for j in range(n):
        v = a[j]
        for c in range(r):
            v -= Z[j, c] * zr[c]
        post[j] = v
    for t in range(k):
        post[S[t]] = 0.0
    trinv = 0.0
    for t in range(k):  # tr(N[S,S]⁻¹): column t of the inverse, its t-th entry
        for u in range(k):
            ys[u] = 1.0 if u == t else 0.0
        _chol_solve(NSS, k, ys)
        trinv += ys[t]
    return trinv


# Eqn. (L6): orthonormal bases of the task's null space and of a reduced robot's.
@_njit
def null_basis(J, Z, QA, hb) -> int:  # pragma: no cover - numba
    """``Z[:, :r]`` an orthonormal basis of ``{q̇ : J q̇ = 0}`` (Householder QR of ``Jᵀ``); r.

    ``Z`` (n, n), ``QA`` (n, m), ``hb`` (m,) scratch. ``J`` has full rank (certified before).
    """
    m, n = J.shape
    for j in range(n):
        for i in range(m):
            QA[j, i] = J[i, j]
    for j in range(m):  # H_j = I − v vᵀ / β on rows j..n−1, v stored in QA[j:, j]
        nrm = 0.0
        for i in range(j, n):
            nrm += QA[i, j] * QA[i, j]
        nrm = math.sqrt(nrm)
        QA[j, j] -= -nrm if QA[j, j] >= 0.0 else nrm
        beta = 0.0
        for i in range(j, n):
            beta += QA[i, j] * QA[i, j]
        hb[j] = beta / 2.0
        if hb[j] == 0.0:
            continue
        for c in range(j + 1, m):
            t = 0.0
            for i in range(j, n):
                t += QA[i, j] * QA[i, c]
            t /= hb[j]
            for i in range(j, n):
                QA[i, c] -= t * QA[i, j]
    r = n - m
    for i in range(n):  # Z = H_0 ... H_{m−1} [0; I]: the last r columns of Q
        for c in range(r):
            Z[i, c] = 1.0 if i == m + c else 0.0
    for j in range(m - 1, -1, -1):
        if hb[j] == 0.0:
            continue
        for c in range(r):
            t = 0.0
            for i in range(j, n):
                t += QA[i, j] * Z[i, c]
            t /= hb[j]
            for i in range(j, n):
                Z[i, c] -= t * QA[i, j]
    return r


@_inline_once
def reduced_basis(Z, r, S, k, Zs, w) -> int:  # pragma: no cover - numba
    """``Zs[:, :r − k]``: orthonormal basis of ``{q̇ : J q̇ = 0, q̇_S = 0}`` from ``Z``; ``r − k``.

    For each locked joint ``i`` a Householder reflection of the columns maps row ``i`` of the
    basis onto its last column, which is dropped; the other columns keep row ``i`` at ~1e-16 (set
    to 0). A joint that cannot move keeps rows of ~1e-16, as the reference's eigenvectors do.
    ``w`` (r,) is scratch. −1 when a locked joint's row is zero (N_ii = 0: refused before).
    """
    n = Zs.shape[0]
    for i in range(n):
        for c in range(r):
            Zs[i, c] = Z[i, c]
    rc = r
    for t in range(k):
        i = S[t]
        nrm = 0.0
        for c in range(rc):
            w[c] = Zs[i, c]
            nrm += w[c] * w[c]
        nrm = math.sqrt(nrm)
        if nrm == 0.0:
            return -1
        last = rc - 1
        w[last] -= -nrm if w[last] >= 0.0 else nrm  # w = v − α e_last, α = −sign(v_last) ‖v‖
        beta = 0.0
        for c in range(rc):
            beta += w[c] * w[c]
        for j in range(n):
            d = 0.0
            for c in range(rc):
                d += Zs[j, c] * w[c]
            d *= 2.0 / beta
            for c in range(rc):
                Zs[j, c] -= d * w[c]
        rc -= 1
        for c in range(rc):
            Zs[i, c] = 0.0
    return rc


@_inline_once
def undamped(J, S, k, bound, params, Gs) -> float:  # pragma: no cover - numba
    """The damping ``μ²`` the reference's projection of ``J_S`` takes: 0, > 0, or −1 (refused).

    First the certificate ``trace((J_S J_Sᵀ)⁻¹) ≤ trace(G⁻¹) λ_max(N[S,S]⁻¹) = bound ≤
    TRACE_MAX`` (0); else the eigenvalues of ``J_S J_Sᵀ``: ``λ_min`` clear of ``SIGMA_EPS²`` by a
    relative margin of 1e-8 either way, so rounding cannot flip the reference's choice (0, or its
    ``μ² = DAMPING² (1 − λ_min/SIGMA_EPS²)``), and clear of its rank threshold; −1 otherwise.
    ``Gs`` (m, m) gets ``J_S J_Sᵀ`` unless the certificate needs no rank test (``params[2] = 0``).
    """
    m, n = J.shape
    if bound <= params[0] and params[2] == 0.0:  # the common case: certified, no rank test
        return 0.0
    fro = 0.0
    for i in range(m):
        for j in range(i + 1):
            t = 0.0
            for c in range(n):
                locked = False
                for u in range(k):
                    locked = locked or S[u] == c
                if not locked:
                    t += J[i, c] * J[j, c]
            Gs[i, j] = t
            Gs[j, i] = t
        fro += Gs[i, i]
    if bound <= params[0] and params[2] * fro * bound < 1.0:
        return 0.0
    lam = np.linalg.eigvalsh(Gs.copy())
    if not lam[0] > (1.0 + 1e-8) * RANK_RTOL**2 * lam[-1]:
        return -1.0
    eps2 = 1.0 / params[0]  # SIGMA_EPS²
    if lam[0] > (1.0 + 1e-8) * eps2:
        return 0.0
    if lam[0] < (1.0 - 1e-8) * eps2:
        return DAMPING**2 * (1.0 - max(lam[0], 0.0) / eps2)
    return -1.0


# The reference's damped least-norm rates of a reduced robot near its singularity.
@_njit
def damped_rates(J, xdot, S, k, Gs, mu2, out, y) -> bool:  # pragma: no cover - numba
    """``out = J_Sᵀ (J_S J_Sᵀ + μ² I)⁻¹ ẋ`` in full size (0 on ``S``); ``Gs`` holds ``J_S J_Sᵀ``.

    ``y`` (≥ m,) is scratch. False when the factorisation fails.
    """
    m, n = J.shape
    for i in range(m):
        Gs[i, i] += mu2
    if not _cholesky(Gs, m):
        return False
    for i in range(m):
        y[i] = xdot[i]
    _chol_solve(Gs, m, y)
    for j in range(n):
        t = 0.0
        for i in range(m):
            t += J[i, j] * y[i]
        out[j] = t
    for u in range(k):
        out[S[u]] = 0.0
    return True


@_njit
def null_project(Z, r, c, zr, out) -> None:  # pragma: no cover - numba
    """``out = Z[:, :r] Z[:, :r]ᵀ c`` (``N c`` for an orthonormal basis); ``c`` may be ``out``; ``zr`` scratch."""
    n = Z.shape[0]
    for u in range(r):
        t = 0.0
        for j in range(n):
            t += Z[j, u] * c[j]
        zr[u] = t
    for j in range(n):
        t = 0.0
        for u in range(r):
            t += Z[j, u] * zr[u]
        out[j] = t
