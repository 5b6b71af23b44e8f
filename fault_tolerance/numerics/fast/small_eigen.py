"""Eigenvalues of a small symmetric matrix, compiled, without allocation (LAPACK's dsyevd path).

``np.linalg.eigvalsh`` of a 6 x 6 inside a numba kernel costs about 2 µs, most of it the wrapper
(workspace query, copies, allocation). The simulated sample needs the extreme eigenvalues of one
such matrix per scenario (``k_S``, eq. 15) and of ``G`` (``σ_min``). This module does what
LAPACK's ``dsyevd`` does for eigenvalues only, in scalar loops on caller-owned storage:

1. :func:`tridiagonalize` — Householder reduction ``A = Q T Qᵀ`` of the lower triangle
   (``dsytd2``, ``uplo = 'L'``);
2. :func:`tridiagonal_eigenvalues` — the square-root-free implicit QL iteration of Pal, Walker
   and Kahan on ``T`` (``dsterf``): it works on the squared off-diagonal, one division pair per
   rotation, Wilkinson-type shift, a 2 x 2 block in closed form (``dlae2``); a block is reversed
   (QR instead of QL) when its last diagonal entry is the smaller, as ``dsterf`` chooses.

Both are backward stable: the eigenvalues are those of a matrix within a few ``ε ‖A‖`` of ``A``.
The functions return False, and the caller falls back to ``np.linalg.eigvalsh``, when the QL
iteration does not converge in ``30 m`` sweeps or a number is not finite (``dsterf``'s scaling of
huge or tiny matrices is left to that fallback).

Example::

    >>> import numpy as np
    >>> from fault_tolerance.numerics.fast.small_eigen import extreme_eigenvalues
    >>> A = np.array([[2.0, 1.0], [1.0, 2.0]]); work = np.empty(3 * 2)
    >>> extreme_eigenvalues(A.copy(), 2, work)
    (1.0, 3.0, True)
"""

from __future__ import annotations

import math

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit

#: LAPACK's ``dlamch('E')``: the unit round-off 2⁻⁵³, and its square (``dsterf``'s ``eps2``).
EPS = 2.0**-53
EPS2 = EPS * EPS
#: ``dsterf`` scales a matrix whose largest entry is outside ``[SMALLEST, LARGEST]`` (its
#: ``ssfmin``, ``ssfmax``: squares of entries would under- or overflow); we hand it to LAPACK.
SMALLEST = math.sqrt(2.2250738585072014e-308) / EPS2
LARGEST = math.sqrt(1.0 / 2.2250738585072014e-308) / 3.0


@njit
def tridiagonalize(A, m, d, e, w) -> None:  # pragma: no cover - numba
    """Householder ``A[:m, :m] = Q T Qᵀ`` from its lower triangle (``dsytd2``), ``A`` overwritten.

    ``T`` has diagonal ``d[:m]`` and off-diagonal ``e[:m-1]``; ``w`` is m scratch numbers. The
    reflector ``H_k = I − τ_k v vᵀ`` that annihilates column ``k`` below ``k+1`` is kept (``Q =
    H_0 H_1 …``): ``v = A[k+1:, k]`` (``A[k+1, k] = 1``), ``τ_k = A[k, k+1]`` (the upper triangle).
    """
    for k in range(m - 1):
        x0 = A[k + 1, k]
        s = 0.0
        for i in range(k + 2, m):
            s += A[i, k] * A[i, k]
        d[k] = A[k, k]
        if s == 0.0:  # nothing to annihilate: H_k = I (dlarfg's xnorm = 0)
            e[k] = x0
            A[k, k + 1] = 0.0
            continue
        beta = -math.copysign(math.sqrt(x0 * x0 + s), x0)
        tau = (beta - x0) / beta
        scale = 1.0 / (x0 - beta)
        A[k + 1, k] = 1.0
        for i in range(k + 2, m):
            A[i, k] *= scale
        _symmetric_rank2(A, k, m, tau, w)
        e[k] = beta
        A[k, k + 1] = tau
    d[m - 1] = A[m - 1, m - 1]


@_inline_once
def _symmetric_rank2(A, k, m, tau, w) -> None:  # pragma: no cover - numba
    """``A' = H A H`` on the trailing block ``k+1:m`` (lower triangle), ``v = A[k+1:, k]``.

    ``w = τ A v − ½ τ² (vᵀA v) v``, then ``A' = A − v wᵀ − w vᵀ`` (``dsymv`` and ``dsyr2``).
    """
    for i in range(k + 1, m):
        w[i] = 0.0
    for j in range(k + 1, m):  # w = τ A v from the lower triangle (dsymv, 'L')
        t1 = tau * A[j, k]
        t2 = 0.0
        w[j] += t1 * A[j, j]
        for i in range(j + 1, m):
            w[i] += t1 * A[i, j]
            t2 += A[i, j] * A[i, k]
        w[j] += tau * t2
    vw = 0.0
    for i in range(k + 1, m):
        vw += w[i] * A[i, k]
    alpha = -0.5 * tau * vw
    for i in range(k + 1, m):
        w[i] += alpha * A[i, k]
    for j in range(k + 1, m):  # dsyr2, 'L'
        vj, wj = A[j, k], w[j]
        for i in range(j, m):
            A[i, j] -= A[i, k] * wj + w[i] * vj


@_inline_once
def pair_eigenvalues(a, b, c):  # pragma: no cover - numba
    """Eigenvalues ``(ρ₁, ρ₂)`` of ``[[a, b], [b, c]]``, ``|ρ₁| ≥ |ρ₂|`` (LAPACK's ``dlae2``).

    The smaller one comes from the determinant, ``ρ₂ = (a c − b²) / ρ₁``, not by cancellation.
    """
    sm, adf, ab = a + c, abs(a - c), abs(2.0 * b)
    acmx, acmn = (a, c) if abs(a) > abs(c) else (c, a)
    if adf > ab:
        rt = adf * math.sqrt(1.0 + (ab / adf) ** 2)
    elif adf < ab:
        rt = ab * math.sqrt(1.0 + (adf / ab) ** 2)
    else:
        rt = ab * math.sqrt(2.0)
    if sm == 0.0:
        return 0.5 * rt, -0.5 * rt
    rt1 = 0.5 * (sm + rt) if sm > 0.0 else 0.5 * (sm - rt)
    return rt1, (acmx / rt1) * acmn - (b / rt1) * b


@_inline_once
def _ql_sweep(d, e2, lo, j) -> None:  # pragma: no cover - numba
    """One implicit QL step on the block ``lo..j`` (squared off-diagonal ``e2``), PWK's rotations.

    The shift is the eigenvalue of the leading 2 x 2 nearer ``d[lo]`` (``dsterf``).
    """
    rte = math.sqrt(e2[lo])
    p = d[lo]
    g = (d[lo + 1] - p) / (2.0 * rte)
    sigma = p - rte / (g + math.copysign(math.hypot(g, 1.0), g))
    c, s = 1.0, 0.0
    gamma = d[j] - sigma
    p = gamma * gamma
    for i in range(j - 1, lo - 1, -1):
        bb = e2[i]
        r = p + bb
        if i != j - 1:
            e2[i + 1] = s * r
        oldc = c
        c = p / r
        s = bb / r
        oldgam = gamma
        gamma = c * (d[i] - sigma) - s * oldgam
        d[i + 1] = oldgam + (d[i] - gamma)
        p = gamma * gamma / c if c != 0.0 else oldc * bb
    e2[lo] = s * p
    d[lo] = sigma + gamma


@_inline_once
def _reverse(d, e2, lo, hi) -> None:  # pragma: no cover - numba
    """Reverse the block ``lo..hi`` of ``T`` (``P T P``: same eigenvalues; QL on it is QR on ``T``)."""
    i, k = lo, hi
    while i < k:
        d[i], d[k] = d[k], d[i]
        i, k = i + 1, k - 1
    i, k = lo, hi - 1
    while i < k:
        e2[i], e2[k] = e2[k], e2[i]
        i, k = i + 1, k - 1


@njit
def _block_end(d, e2, lo, m) -> int:  # pragma: no cover - numba
    """First ``j ≥ lo`` with a negligible ``e_j`` (``e_j² ≤ ε² |d_j d_{j+1}|``), else ``m − 1``."""
    for j in range(lo, m - 1):
        if e2[j] <= EPS2 * abs(d[j] * d[j + 1]):
            e2[j] = 0.0
            return j
    return m - 1


@_inline_once
def _block_eigenvalues(d, e2, lo, hi, budget) -> int:  # pragma: no cover - numba
    """QL on the unreduced block ``lo..hi`` until it is diagonal; the sweeps left, -1 if none."""
    if abs(d[hi]) < abs(d[lo]):
        _reverse(d, e2, lo, hi)
    while lo <= hi:
        j = _block_end(d, e2, lo, hi + 1)
        if j == lo:  # d[lo] is an eigenvalue
            lo += 1
        elif j == lo + 1:  # a 2 x 2 block in closed form
            d[lo], d[lo + 1] = pair_eigenvalues(d[lo], math.sqrt(e2[lo]), d[lo + 1])
            e2[lo] = 0.0
            lo += 2
        elif budget == 0:
            return -1
        else:
            budget -= 1
            _ql_sweep(d, e2, lo, j)
    return budget


@njit
def _in_range(d, e, m) -> bool:  # pragma: no cover - numba
    """Whether ``max(|d|, |e|)`` is 0 or in ``[SMALLEST, LARGEST]`` (False for inf and NaN)."""
    big = 0.0
    for j in range(2 * m - 1):
        x = abs(d[j]) if j < m else abs(e[j - m])
        if not x <= LARGEST:
            return False
        big = max(big, x)
    return big == 0.0 or big >= SMALLEST


@_inline_once
def tridiagonal_eigenvalues(d, e, m) -> bool:  # pragma: no cover - numba
    """Eigenvalues of ``T`` (diagonal ``d[:m]``, off-diagonal ``e[:m-1]``) into ``d``, unsorted.

    ``dsterf``'s iteration; ``e`` is overwritten. False if the largest entry is not finite or
    outside ``[SMALLEST, LARGEST]`` (and not 0), if ``30 m`` sweeps do not converge, or if a
    result is not finite.
    """
    if not _in_range(d, e, m):
        return False
    for j in range(m - 1):
        e[j] = e[j] * e[j]
    budget = 30 * m
    lo = 0
    while lo < m:
        hi = _block_end(d, e, lo, m)
        if hi > lo:
            budget = _block_eigenvalues(d, e, lo, hi, budget)
            if budget < 0:
                return False
        lo = hi + 1
    for j in range(m):
        if not abs(d[j]) < math.inf:
            return False
    return True


@_inline_once
def symmetric_eigenvalues(A, m, work) -> bool:  # pragma: no cover - numba
    """Eigenvalues of symmetric ``A[:m, :m]`` (lower triangle read) into ``work[:m]``, unsorted.

    ``A`` is overwritten; ``work`` holds at least ``3 m`` numbers. False when the caller must
    use ``np.linalg.eigvalsh`` (no convergence, or a number that is not finite).
    """
    d, e, w = work[0:m], work[m : 2 * m], work[2 * m : 3 * m]
    if m == 1:
        d[0] = A[0, 0]
        return abs(d[0]) < math.inf
    tridiagonalize(A, m, d, e, w)
    return tridiagonal_eigenvalues(d, e, m)


@njit
def extreme_eigenvalues(A, m, work):  # pragma: no cover - numba
    """``(λ_min, λ_max, ok)`` of symmetric ``A[:m, :m]``; see :func:`symmetric_eigenvalues`."""
    if not symmetric_eigenvalues(A, m, work):
        return math.nan, math.nan, False
    lo = hi = work[0]
    for j in range(1, m):
        lo = min(lo, work[j])
        hi = max(hi, work[j])
    return lo, hi, True
