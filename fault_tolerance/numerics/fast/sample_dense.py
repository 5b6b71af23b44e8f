"""The small dense linear algebra of one simulated sample, compiled: Cholesky, downdates, ``k_S``.

Used by :func:`fault_tolerance.simulation.fast.sample.sample_kernel`: the Cholesky factor of ``G =
J Jᵀ`` (``G`` kept), the reduced Gram matrices ``G − J_i J_iᵀ`` and their extreme eigenvalues
(eq. 15). The sample's rates, pivots ``N_ii`` and products ``N v`` are not here: they are the
Controller's compiled step's own kernels (``Y = L⁻¹J``, ``N = I − YᵀY`` never formed,
:mod:`fault_tolerance.control.fast.step`). Plain Python loops, valid without numba; compiled by
numba when it is installed (cached on disk).
"""

from __future__ import annotations

import math

import numpy as np

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit
from fault_tolerance.numerics.fast.dense import cholesky_into, trace_inverse
from fault_tolerance.numerics.fast.rank_one_eigen import downdate_extremes, eigenpairs
from fault_tolerance.numerics.fast.small_eigen import extreme_eigenvalues

#: Indices into ``params`` (shared with :mod:`fault_tolerance.simulation.fast.sample`); the first
#: four are laid out as the Controller's compiled step's (``[TRACE_MAX, pivot threshold, rank
#: coefficient, alpha]``, :func:`fault_tolerance.control.fast.step.step_kernel`).
P_TRACE, P_PIVOT, P_RANK, P_ALPHA, P_GAIN, P_MAXSTEP, P_RCN_MAX, P_CONT, P_LOCK = range(9)
P_DT, P_DECAY, P_ACCEL, P_BOUNDED = 9, 10, 11, 12
N_PARAMS = 13


_cholesky = cholesky_into  # G = L Lᵀ into L, G kept (compiled_linalg)
_trace_inverse = trace_inverse


@njit
def _downdate(G, J, i, W) -> None:  # pragma: no cover - numba
    """``W = G − J_i J_iᵀ = J_S J_Sᵀ`` of the scenario locking joint ``i``."""
    m = G.shape[0]
    for r in range(m):
        for c in range(m):
            W[r, c] = G[r, c] - J[r, i] * J[c, i]


@_inline_once
def _reduced_extremes(G, J, i, W, t):  # pragma: no cover - numba
    """``(λ_min, λ_max)`` of ``J_S J_Sᵀ`` (scenario ``i``): :mod:`.small_eigen`, else LAPACK's."""
    m = G.shape[0]
    _downdate(G, J, i, W)
    lo, hi, ok = extreme_eigenvalues(W, m, t)
    if ok:
        return lo, hi
    _downdate(G, J, i, W)  # W was overwritten
    lam = np.linalg.eigvalsh(W)
    return lam[0], lam[m - 1]


@_inline_once
def _sigma_min(G, W, t) -> float:  # pragma: no cover - numba
    """``σ_min(J) = √λ_min(G)``: :mod:`.small_eigen` on a copy in ``W``, else LAPACK's."""
    m = G.shape[0]
    for r in range(m):
        for c in range(m):
            W[r, c] = G[r, c]
    lo, hi, ok = extreme_eigenvalues(W, m, t)
    if not ok:
        lo = np.linalg.eigvalsh(G)[0]
    return math.sqrt(max(lo, 0.0))


@_inline_once
def _capped_k(lo, hi, rcn_max) -> float:  # pragma: no cover - numba
    """``k = σ_max / σ_min`` from ``λ_min, λ_max`` of ``J_S J_Sᵀ``, capped at ``rcn_max``."""
    smax = math.sqrt(max(hi, 0.0))
    smin = max(math.sqrt(max(lo, 0.0)), smax / rcn_max)
    k = smax / smin if smax > 0.0 else rcn_max  # smin >= smax / rcn_max > 0 then
    return min(k, rcn_max)


# Eq. (15)
@_inline_once
def _spectra(G, J, cols, ks, W, rcn_max, scratch):  # pragma: no cover - numba
    """``k_S`` of every scenario into ``ks``; ``(K, σ_min(J))``, from one eigenbasis of ``G``.

    ``G = Vtᵀ diag(d) Vt`` once (:func:`.rank_one_eigen.eigenpairs`); each ``J_S J_Sᵀ = G − J_i
    J_iᵀ`` by its secular equation (:func:`.rank_one_eigen.downdate_extremes`). A scenario whose
    roots fail, or all when the eigenbasis fails, takes :func:`_reduced_extremes` (QL, then
    LAPACK); ``W`` (m, m) and ``scratch`` (``m² + 5 m``: ``Vt``, ``d``, ``u²``, 3 m) are scratch.
    """
    m = G.shape[0]
    Vt = scratch[0 : m * m].reshape((m, m))
    d, u2, t = (
        scratch[m * m : m * m + m],
        scratch[m * m + m : m * m + 2 * m],
        scratch[m * m + 2 * m :],
    )
    for r in range(m):
        for c in range(m):
            W[r, c] = G[r, c]
    basis = eigenpairs(W, m, Vt, d, t)
    K = 0.0
    for s in range(cols.shape[0]):
        ok = False
        if basis:
            lo, hi, ok = downdate_extremes(Vt, d, J, cols[s], m, u2)
        if not ok:
            lo, hi = _reduced_extremes(G, J, cols[s], W, t)
        ks[s] = _capped_k(lo, hi, rcn_max)
        K += ks[s] * ks[s]
    smin = math.sqrt(max(d[0], 0.0)) if basis else _sigma_min(G, W, t)
    return K, smin
