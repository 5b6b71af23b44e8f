"""JVJA, the minimum joint-velocity-jump algorithm: eq. (5), in closed form (G2), and (G3).

Its options (:class:`JvjaOptions`): ``weights`` of the scenarios and the post-failure
``response`` (``"least_norm"``, the paper's, or ``"continuation"``, MATH.md (G3)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import Projection, damped_pivots, pivot_block, projection
from fault_tolerance.resolution.indices import RESPONSES
from fault_tolerance.resolution.scenarios import Scenarios, scenarios


@dataclass(frozen=True)
class JvjaOptions:
    """JVJA's options: scenario ``weights`` (default 1 each) and the post-failure ``response``."""

    weights: Sequence[float] | None = None
    response: str = "least_norm"

    def __post_init__(self) -> None:
        if self.response not in RESPONSES:
            raise InvalidInput(f"response {self.response!r} is not one of {list(RESPONSES)}")


def _scenarios(J: np.ndarray, lockable, weights, joint_names) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def _unit_weights(sc: Scenarios) -> np.ndarray:
    """The weights over the largest: eq. (5) does not change, and their sum cannot overflow."""
    return sc.weights / sc.weights.max()


# Eqn. (5), in closed form (G2); (G3) for the continuation response.
def jvja(
    J: np.ndarray,
    xdot: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    joint_names: Sequence[str] = (),
    tolerate: bool = False,
    proj: Projection | None = None,
) -> np.ndarray:
    r"""JVJA, minimum square-sum joint velocity jump, eq. (5).

    Least-norm response (the paper's): :math:`\dot q = a - \frac{1}{W}\sum_S w_S N_{:,S}
    N_{S,S}^{-1} a_S`, :math:`a = J^+\dot x`, :math:`W = \sum_S w_S`; for single-joint scenarios
    (G2) :math:`\dot q = a - N c / W`, :math:`c_i = w_i a_i / N_{ii}`. One pseudo-inverse per step.

    Continuation response (G3): :math:`\dot q = a + N z`, :math:`z = -(N W N)^+ N W a` with
    :math:`W = \sum_S w_S E_S N_{S,S}^{-1} E_S^T`.

    ``proj``: the :func:`~.linalg.projection` of ``J`` when the caller has it already.

    ``tolerate=True`` (used by the simulation after its first step) damps the pivots of ``N[S, S]``
    below ``linalg.PIVOT_EPS`` instead of raising: the rates stay finite when the path crosses a
    singularity of a reduced Jacobian (the scenario is intolerable only there).

    Raises:
        IntolerableFailure: a scenario's ``N[S, S]`` is singular (locking it loses the task), unless
            ``tolerate``.
    """
    sc = _scenarios(J, lockable, weights, joint_names)
    proj = proj or projection(J)
    N = proj.N
    a = proj.Jpinv @ xdot
    pivots = damped_pivots(sc.pivots(N)) if tolerate else sc.check_tolerable(N)
    return jvja_rates(a, N, sc, pivots, response, tolerate)


# Eqn. (5) from a = J⁺ẋ and N, (G2) and (G3): the one implementation of JVJA's rates.
def jvja_rates(
    a: np.ndarray,
    N: np.ndarray,
    sc: Scenarios,
    pivots: np.ndarray,
    response: str = "least_norm",
    damp: bool = False,
) -> np.ndarray:
    """JVJA's rates from ``a`` (n,) and ``N`` (n, n), or stacks ``a`` (..., n), ``N`` (..., n, n).

    ``pivots`` (f,) or (..., f): the smallest eigenvalues of the ``N[S, S]`` (checked or damped by
    the caller); ``damp``: the multi-joint blocks damped the same way. The batched API calls this
    on stacks, :func:`jvja` on one configuration.
    """
    w = _unit_weights(sc)
    if response == "least_norm":
        if sc.singletons:
            c = np.zeros_like(a)
            c[..., sc.columns] = w * a[..., sc.columns] / pivots
            if a.ndim == 1:
                return a - N @ c / w.sum()
            return a - np.einsum("...ij,...j->...i", N, c) / w.sum()
        shift = sum(
            wS * _block_solve(N, list(S), a, damp) for S, wS in zip(sc.sets, w, strict=True)
        )
        return a - shift / w.sum()
    if response == "continuation":
        W = np.zeros_like(N)
        for S, wS in zip(sc.sets, w, strict=True):
            rows, cols = np.ix_(S, S)
            W[..., rows, cols] += wS * np.linalg.inv(pivot_block(N, S, damp))
        NW = N @ W
        G = np.linalg.pinv(NW @ N, rcond=1e-10, hermitian=True)
        if a.ndim == 1:
            return a + N @ (-G @ (NW @ a))
        z = -np.einsum("...ij,...j->...i", G, np.einsum("...ij,...j->...i", NW, a))
        return a + np.einsum("...ij,...j->...i", N, z)
    raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")


def _block_solve(N: np.ndarray, S: list[int], a: np.ndarray, damp: bool) -> np.ndarray:
    """``N[:, S] N[S, S]⁻¹ a_S`` of one projector (n,) or of a stack (..., n)."""
    M = pivot_block(N, S, damp)
    if a.ndim == 1:
        return N[:, S] @ np.linalg.solve(M, a[S])
    return (N[..., :, S] @ np.linalg.solve(M, a[..., S][..., None]))[..., 0]


# Eqn. (5) the explicit way: one pseudo-inverse per scenario (reference, slow).
def jvja_explicit(J: np.ndarray, xdot: np.ndarray, lockable=None, *, weights=None) -> np.ndarray:
    """Eq. (5) with ``ˢq̇' = E_S J_S⁺ ẋ`` from NumPy's SVD pseudo-inverse for every scenario."""
    from fault_tolerance.numerics.linalg import reduced_rates_explicit

    sc = _scenarios(J, lockable, weights, ())
    Jp = np.linalg.pinv(J)
    N = np.eye(J.shape[1]) - Jp @ J
    post = np.array([reduced_rates_explicit(J, xdot, S) for S in sc.sets])
    w = _unit_weights(sc)
    mean = w @ post / w.sum()
    return Jp @ xdot + N @ mean
