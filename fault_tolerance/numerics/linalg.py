"""Linear algebra of redundancy resolution: pseudo-inverse, null-space projector, reduced rates.

Everything comes from one symmetric eigendecomposition of the small ``m x m`` matrix ``J Jᵀ``:
with ``J Jᵀ = V Λ Vᵀ`` the singular values of ``J`` are ``√Λ``, the right singular vectors are
``U = Jᵀ V Λ^{-1/2}``, the least-norm rates are ``a = Jᵀ V Λ⁻¹ Vᵀ ẋ`` and the null-space projector
is ``N = I - U Uᵀ``.

Near a singularity of ``J`` (smallest singular value below :data:`SIGMA_EPS`) the least-norm
rates are damped (variable damping of Nakamura & Hanafusa / Maciejewski & Klein): ``Λ⁻¹`` becomes
``(Λ + μ²)⁻¹`` with ``μ² = DAMPING² (1 - (σ_min / SIGMA_EPS)²)``, so the rates stay finite and
the task is tracked approximately; singular directions with ``σ < RANK_RTOL σ_max`` are dropped
from ``U``, so ``N`` stays an exact projector onto the numerical null space.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

#: Smallest singular value of J [task units per rad] below which the least-norm rates are damped.
SIGMA_EPS = 1e-3
#: Largest damping factor μ [task units per rad], reached when σ_min = 0.
DAMPING = 1e-2
#: Singular values below RANK_RTOL · σ_max count as zero (rank deficiency).
RANK_RTOL = 1e-9
#: A scenario is intolerable when the smallest eigenvalue of N[S, S] is below this.
PIVOT_TOL = 1e-9
#: Pivots of N[S, S] below PIVOT_EPS are damped where near-intolerable scenarios are tolerated (a
#: simulation after its first step): p → p + PIVOT_DAMPING² (1 − (p/PIVOT_EPS)²), never below
#: PIVOT_DAMPING², so the reduced rates and JVJA's rates stay finite through a reduced singularity.
PIVOT_EPS = 1e-4
PIVOT_DAMPING = 1e-2


class Projection(NamedTuple):
    """``J⁺`` and ``N`` of one Jacobian, and how close ``J`` is to a singularity."""

    Jpinv: np.ndarray  # shape (n, m), damped near singularities
    N: np.ndarray  # shape (n, n), symmetric, idempotent, J N = 0
    sigma_min: float  # smallest singular value of J
    damped: bool  # True when sigma_min < SIGMA_EPS


def damping_factor(sigma_min: float) -> float:
    """Variable damping ``μ² = DAMPING² (1 - (σ_min/SIGMA_EPS)²)`` below SIGMA_EPS, else 0."""
    if sigma_min >= SIGMA_EPS:
        return 0.0
    return DAMPING**2 * (1.0 - (sigma_min / SIGMA_EPS) ** 2)


def projection(J: np.ndarray) -> Projection:
    """Pseudo-inverse and null-space projector from one eigendecomposition of ``J Jᵀ``.

    ``J⁺ = Jᵀ (J Jᵀ)⁻¹`` (damped near singularities, see the module doc) and ``N = I - J⁺J``.
    """
    J = np.asarray(J, dtype=float)
    m, n = J.shape
    lam, V = np.linalg.eigh(J @ J.T)  # ascending, lam = σ²
    lam = np.maximum(lam, 0.0)
    sigma_min = float(np.sqrt(lam[0]))
    mu2 = damping_factor(sigma_min)
    Jpinv = J.T @ (V / (lam + mu2 + (lam + mu2 == 0.0))) @ V.T
    keep = lam > (RANK_RTOL**2) * max(lam[-1], 1e-300)
    U = (J.T @ V[:, keep]) / np.sqrt(lam[keep])
    N = np.eye(n) - U @ U.T
    return Projection(Jpinv, N, sigma_min, mu2 > 0.0)


def pinv(J: np.ndarray) -> np.ndarray:
    """Moore-Penrose inverse ``J⁺ = Jᵀ (J Jᵀ)⁻¹`` (damped near singularities), shape (n, m)."""
    return projection(J).Jpinv


def nullspace_projector(J: np.ndarray) -> np.ndarray:
    """``N = I - J⁺J``: symmetric, idempotent, ``J N = 0``, shape (n, n)."""
    return projection(J).N


def damped_pivots(p):
    """Pivots ``p + μ²``, ``μ² = PIVOT_DAMPING² (1 - (p/PIVOT_EPS)²)`` below PIVOT_EPS, else ``p``."""
    p = np.maximum(np.asarray(p, dtype=float), 0.0)
    mu2 = np.where(p < PIVOT_EPS, PIVOT_DAMPING**2 * (1.0 - (p / PIVOT_EPS) ** 2), 0.0)
    return p + mu2


def pivot_block(N: np.ndarray, S: Sequence[int], damp: bool = False) -> np.ndarray:
    """``N[S, S]``; with ``damp`` its smallest eigenvalue raised to :func:`damped_pivots` of itself."""
    S = list(S)
    M = N[np.ix_(S, S)]
    if damp:
        lam = float(np.linalg.eigvalsh(M)[0])
        M = M + (float(damped_pivots(lam)) - lam) * np.eye(len(S))
    return M


def min_pivot(N: np.ndarray, S: Sequence[int]) -> float:
    """Smallest eigenvalue of ``N[S, S]``; zero means locking ``S`` loses the task."""
    S = list(S)
    if len(S) == 1:
        return float(N[S[0], S[0]])
    return float(np.linalg.eigvalsh(N[np.ix_(S, S)])[0])


# Eqn. (2) in closed form (G1).
def reduced_rates(a: np.ndarray, N: np.ndarray, S: Sequence[int], damp: bool = False) -> np.ndarray:
    r"""Rates of the reduced robot with joints ``S`` locked, eq. (2) in closed form (G1).

    :math:`{}^S\dot q' = a - N_{:,S} N_{S,S}^{-1} a_S`, with :math:`a = J^+\dot x`.
    Shape (n,); entries in ``S`` are zero. The caller checks ``N[S, S]`` is not singular, or asks
    for ``damp``: pivots below :data:`PIVOT_EPS` damped (:func:`damped_pivots`), always finite.
    """
    S = list(S)
    if len(S) == 1:
        i = S[0]
        piv = float(damped_pivots(N[i, i])) if damp else N[i, i]
        qd = a - (a[i] / piv) * N[:, i]
        qd[i] = 0.0
        return qd
    qd = a - N[:, S] @ np.linalg.solve(pivot_block(N, S, damp), a[S])
    qd[S] = 0.0
    return qd


# docs/MATH.md (G3), continuation response.
def continuation_rates(qd: np.ndarray, N: np.ndarray, S: Sequence[int]) -> np.ndarray:
    r"""Rates the reduced robot takes when it keeps the solution nearest to ``qd`` (G3).

    :math:`{}^S\dot q'' = \dot q - N_{:,S} N_{S,S}^{-1} \dot q_S`. Shape (n,), zero in ``S``.
    """
    return reduced_rates(qd, N, S)


def reduced_rates_explicit(J: np.ndarray, xdot: np.ndarray, S: Sequence[int]) -> np.ndarray:
    """Eq. (2) the slow way: ``E_S J_S⁺ ẋ`` with NumPy's SVD pseudo-inverse (reference for tests)."""
    n = J.shape[1]
    keep = [j for j in range(n) if j not in set(S)]
    qd = np.zeros(n)
    qd[keep] = np.linalg.pinv(J[:, keep]) @ xdot
    return qd
