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
from typing import Any, NamedTuple

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
    """``J⁺`` and ``N`` of one Jacobian (or of a stack), and how close ``J`` is to a singularity.

    For a stack of Jacobians (..., m, n) every field has the stack's leading axes.
    """

    Jpinv: np.ndarray  # shape (..., n, m), damped near singularities
    N: np.ndarray  # shape (..., n, n), symmetric, idempotent, J N = 0
    sigma_min: Any  # smallest singular value of J: float, or (...,) for a stack
    damped: Any  # sigma_min < SIGMA_EPS: bool, or (...,) for a stack


def damping_factor(sigma_min):
    """Variable damping ``μ² = DAMPING² (1 - (σ_min/SIGMA_EPS)²)`` below SIGMA_EPS, else 0.

    Elementwise for an array of ``σ_min``; a float for a float.
    """
    if np.ndim(sigma_min) == 0:
        if sigma_min >= SIGMA_EPS:
            return 0.0
        return DAMPING**2 * (1.0 - (sigma_min / SIGMA_EPS) ** 2)
    s = np.asarray(sigma_min, dtype=float)
    return np.where(s < SIGMA_EPS, DAMPING**2 * (1.0 - (s / SIGMA_EPS) ** 2), 0.0)


def projection(J: np.ndarray) -> Projection:
    """Pseudo-inverse and null-space projector from one eigendecomposition of ``J Jᵀ``.

    ``J⁺ = Jᵀ (J Jᵀ)⁻¹`` (damped near singularities, see the module doc) and ``N = I - J⁺J``.
    ``J`` is one Jacobian (m, n) or a stack (..., m, n): each matrix of a stack gets exactly what
    it would get alone (the batched API and the whole-path planner call it on stacks).
    """
    J = np.asarray(J, dtype=float)
    n = J.shape[-1]
    Jt = np.swapaxes(J, -1, -2)
    lam, V = np.linalg.eigh(J @ Jt)  # ascending, lam = σ²
    lam = np.maximum(lam, 0.0)
    sigma_min = np.sqrt(lam[..., 0])
    mu2 = damping_factor(sigma_min)
    d = lam + np.asarray(mu2)[..., None]
    Jpinv = Jt @ (V / (d + (d == 0.0))[..., None, :]) @ np.swapaxes(V, -1, -2)
    keep = lam > (RANK_RTOL**2) * np.maximum(lam[..., -1:], 1e-300)
    if J.ndim == 2:  # the dropped directions left out of the product (not added as zeros)
        U = (Jt @ V[:, keep]) / np.sqrt(lam[keep])
        return Projection(Jpinv, np.eye(n) - U @ U.T, float(sigma_min), bool(mu2 > 0.0))
    U = np.where(
        keep[..., None, :], (Jt @ V) / np.sqrt(np.where(keep, lam, 1.0))[..., None, :], 0.0
    )
    N = np.eye(n) - U @ np.swapaxes(U, -1, -2)
    return Projection(Jpinv, N, sigma_min, np.asarray(mu2) > 0.0)


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
    """``N[S, S]`` of one projector or of a stack (..., n, n).

    With ``damp`` its smallest eigenvalue is raised to :func:`damped_pivots` of itself.
    """
    S = list(S)
    M = N[..., S, :][..., :, S]
    if damp:
        lam = np.linalg.eigvalsh(M)[..., 0]
        shift = np.asarray(damped_pivots(lam) - lam)[..., None, None]
        M = M + shift * np.eye(len(S))
    return M


def min_pivot(N: np.ndarray, S: Sequence[int]):
    """Smallest eigenvalue of ``N[S, S]``; zero means locking ``S`` loses the task.

    A float for one projector (n, n), an array (...,) for a stack (..., n, n).
    """
    S = list(S)
    p = N[..., S[0], S[0]] if len(S) == 1 else np.linalg.eigvalsh(pivot_block(N, S))[..., 0]
    return float(p) if N.ndim == 2 else p


# Eqn. (2) in closed form (G1).
def reduced_rates(a: np.ndarray, N: np.ndarray, S: Sequence[int], damp: bool = False) -> np.ndarray:
    r"""Rates of the reduced robot with joints ``S`` locked, eq. (2) in closed form (G1).

    :math:`{}^S\dot q' = a - N_{:,S} N_{S,S}^{-1} a_S`, with :math:`a = J^+\dot x`.
    Shape (n,), or (..., n) for stacks ``a`` (..., n) and ``N`` (..., n, n); entries in ``S`` are
    zero. The caller checks ``N[S, S]`` is not singular, or asks for ``damp``: pivots below
    :data:`PIVOT_EPS` damped (:func:`damped_pivots`), always finite.
    """
    S = list(S)
    if len(S) == 1:
        i = S[0]
        piv = damped_pivots(N[..., i, i]) if damp else N[..., i, i]
        qd = a - (a[..., i] / piv)[..., None] * N[..., :, i]
        qd[..., i] = 0.0
        return qd
    M = pivot_block(N, S, damp)
    if a.ndim == 1:
        qd = a - N[:, S] @ np.linalg.solve(M, a[S])
    else:
        qd = a - (N[..., :, S] @ np.linalg.solve(M, a[..., S][..., None]))[..., 0]
    qd[..., S] = 0.0
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
