"""Indices of the paper: joint velocity jump (1, 9, 10) and reduced condition number (15).

Also the fault-tolerance measure ``k_f = min_S σ_min(J_S)`` (Roberts & Maciejewski) and the
reduced manipulability ``w_S = √det(J_S J_Sᵀ)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.checks import finite
from fault_tolerance.numerics.linalg import projection, reduced_rates
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Reduced condition numbers are capped here, so a rank-deficient reduced Jacobian gives a large
#: finite number instead of inf/NaN.
RCN_MAX = 1e8
#: Largest reduced condition number k_S accepted along a planned run (the paper's Sec. III.D (iii)).
RCN_THRESHOLD = 100.0
#: A reduced robot with ``σ_min(J_S) <= σ_max(J_S) / RCN_SINGULAR`` is singular for the gradient of
#: K (eq. S1): its term is 0. There the derivative of σ_min has no sign (moving either way along it
#: raises σ_min alike) and Gram-based routes see σ_min only to ~1e-8 σ_max, so every route leaves
#: the term out at this threshold, far above that noise and below the RCN cap.
RCN_SINGULAR = 1e6

RESPONSES = ("least_norm", "continuation")
#: What :func:`rcn_gradient` does with a singular reduced robot (eq. S1): ``"skip"`` leaves its term
#: out (MDA's direction, one in every route); ``"escape"`` keeps the capped term, whose sign is the
#: SVD's (either sign raises σ_min), for a descent on K that checks each step (the posture search).
SINGULAR_TERMS = ("skip", "escape")


def _scenarios(J: np.ndarray, lockable, weights=None, joint_names=()) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def post_failure_rates(
    a: np.ndarray,
    N: np.ndarray,
    sc: Scenarios,
    qd: np.ndarray | None = None,
    response: str = "least_norm",
    *,
    damp: bool = False,
) -> np.ndarray:
    """Rates of the reduced robot for every scenario, shape (f, n).

    ``response="least_norm"``: eq. (2) ``E_S J_S⁺ ẋ`` in closed form (G1), from ``a = J⁺ẋ``.
    ``response="continuation"``: (G3) the solution nearest to the planned rates ``qd``.
    ``damp``: pivots of ``N[S, S]`` below ``linalg.PIVOT_EPS`` are damped (finite at a reduced
    singularity, where the exact rates are unbounded).
    """
    if response not in RESPONSES:
        raise InvalidInput(f"response {response!r} is not one of {RESPONSES}")
    base = a if response == "least_norm" else qd
    if base is None:
        raise InvalidInput("the continuation response needs the planned rates qd")
    return np.array([reduced_rates(base, N, S, damp) for S in sc.sets])


# Eqn. (1)
def joint_jumps(post: np.ndarray, qd: np.ndarray) -> np.ndarray:
    r"""Per-joint velocity jumps :math:`{}^S\lambda_j = |{}^S\dot q'_j - \dot q_j|`, shape (f, n)."""
    return np.abs(post - qd)


# Eqn. (9), (10)
def square_sum_jump(post: np.ndarray, qd: np.ndarray, weights: np.ndarray) -> float:
    r"""Square-sum jump :math:`\lambda = \sum_S w_S \|{}^S\dot q' - \dot q\|^2` [(rad/s)²]."""
    d = post - qd
    return float(weights @ np.einsum("fn,fn->f", d, d))


def jvj(
    J: np.ndarray,
    xdot: np.ndarray,
    qd: np.ndarray,
    lockable=None,
    *,
    weights: Sequence[float] | None = None,
    response: str = "least_norm",
    per_joint: bool = False,
    joint_names: Sequence[str] = (),
):
    """Square-sum joint velocity jump of rates ``qd``, eq. (9)/(10) [(rad/s)²].

    With ``per_joint=True`` returns the (f, n) array of eq. (1) instead. Under joint limits
    (``bounds=``) see :func:`fault_tolerance.jvj` (:mod:`fault_tolerance.resolution.api`).

    Example:
        >>> import numpy as np, fault_tolerance as ft
        >>> J = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, 0.7]])
        >>> xd = np.array([0.1, 0.0])
        >>> ft.jvj(J, xd, ft.resolve("jvja", J, xd)) <= ft.jvj(J, xd, ft.resolve("lnva", J, xd))
        True
    """
    J = finite(J, "J", ndim=2)
    m, n = J.shape
    xdot, qd = finite(xdot, "xdot", (m,)), finite(qd, "qd", (n,))
    sc = _scenarios(J, lockable, weights, joint_names)
    proj = projection(J)
    sc.check_tolerable(proj.N)
    if response == "continuation":
        _check_rates(J, xdot, qd)
    post = post_failure_rates(proj.Jpinv @ xdot, proj.N, sc, qd, response)
    if per_joint:
        return joint_jumps(post, qd)
    lam = square_sum_jump(post, qd, sc.weights)
    if not np.isfinite(lam):  # λ is quadratic in (ẋ, q̇): beyond float64 for |ẋ| of ~1e154
        raise InvalidInput(
            f"the jump of these rates overflows float64 (|xdot| up to {np.abs(xdot).max():.3g}, "
            f"|qd| up to {np.abs(qd).max():.3g}); scale xdot and qd down (λ scales as their square)"
        )
    return lam


def _check_rates(J: np.ndarray, xdot: np.ndarray, qd: np.ndarray) -> None:
    """The continuation response (G3) continues the rates ``qd``: they must satisfy J q̇ = ẋ."""
    if qd.shape != (J.shape[1],) or xdot.shape != (J.shape[0],):
        raise InvalidInput(f"qd must be ({J.shape[1]},) and xdot ({J.shape[0]},)")
    res = float(np.linalg.norm(J @ qd - xdot))
    scale = float(np.linalg.norm(xdot) + np.linalg.norm(J) * np.linalg.norm(qd))
    if not res <= 1e-6 * scale + 1e-12:
        raise InvalidInput(
            f"response='continuation' continues the rates qd, which must track the task: "
            f"‖J qd − xdot‖ = {res:.3g} (tolerance {1e-6 * scale + 1e-12:.3g}); pass the "
            "rates actually commanded for xdot"
        )


# Eqn. (15)
def reduced_singular_values(J: np.ndarray, sc: Scenarios) -> np.ndarray:
    """Singular values of every reduced Jacobian ``J_S``, ascending, shape (f, m).

    ``J_S J_Sᵀ = J Jᵀ - J[:, S] J[:, S]ᵀ``: the f small ``m x m`` matrices go to one batched
    ``eigvalsh`` call. A stack of Jacobians (..., m, n) gives (..., f, m), each row what it
    would give alone (the batched API and the whole-path planner call it on stacks).
    """
    G = J @ np.swapaxes(J, -1, -2)
    if sc.singletons:
        cols = np.swapaxes(J[..., :, sc.columns], -1, -2)  # (..., f, m)
        stack = G[..., None, :, :] - cols[..., :, None] * cols[..., None, :]
    else:
        parts = [J[..., :, list(S)] for S in sc.sets]
        stack = np.stack([G - C @ np.swapaxes(C, -1, -2) for C in parts], axis=-3)
    lam = np.linalg.eigvalsh(stack)
    return np.sqrt(np.maximum(lam, 0.0))


def condition_numbers(sigma: np.ndarray) -> np.ndarray:
    """``σ_max / σ_min`` of each row of ascending singular values, capped at :data:`RCN_MAX`."""
    smax = sigma[..., -1]
    smin = np.maximum(sigma[..., 0], smax / RCN_MAX)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(smax > 0, smax / np.where(smin > 0, smin, 1.0), RCN_MAX)
    return np.minimum(k, RCN_MAX)


def rcn(J: np.ndarray, lockable=None, *, joint_names: Sequence[str] = ()) -> np.ndarray:
    """Reduced condition numbers ``k_S = σ_max(J_S)/σ_min(J_S) >= 1``, eq. (15), shape (f,)."""
    J = finite(J, "J", ndim=2)
    return condition_numbers(reduced_singular_values(J, _scenarios(J, lockable, None, joint_names)))


def square_sum_rcn(J: np.ndarray, lockable=None) -> float:
    """Square-sum RCN ``K = Σ_S k_S²``, the index the paper plots."""
    k = rcn(J, lockable)
    return float(k @ k)


def rcn_gradient(
    J: np.ndarray,
    dJ: np.ndarray,
    lockable=None,
    *,
    joint_names: Sequence[str] = (),
    singular: str = "skip",
) -> np.ndarray:
    r"""Gradient of ``K = Σ_S k_S²`` with respect to ``q``, shape (n,).

    Singular values move as :math:`\partial\sigma/\partial q_j = u^T (\partial J_S/\partial q_j) v`
    (u, v its singular vectors), so
    :math:`\partial k/\partial q_j = (\sigma_{max}' \sigma_{min} - \sigma_{max}\sigma_{min}')/\sigma_{min}^2`.
    ``dJ`` is ``Arm.jacobian_derivatives(q)``, shape (n, m, n). A singular reduced robot,
    ``σ_min(J_S) <= σ_max(J_S) / RCN_SINGULAR``, adds nothing (eq. S1 in docs/MATH.md): the one
    definition of MDA's direction there, which every route (Controller, simulate) follows.
    ``singular="escape"`` keeps that term instead, capped at ``k_S = RCN_MAX``: a direction that
    raises its ``σ_min`` (either sign does), for a descent on K that accepts only decreases.
    """
    if singular not in SINGULAR_TERMS:
        raise InvalidInput(f"unknown singular={singular!r}; allowed: {', '.join(SINGULAR_TERMS)}")
    J = finite(J, "J", ndim=2)
    m, n = J.shape
    dJ = finite(dJ, "dJ", (n, m, n))
    sc = _scenarios(J, lockable, None, joint_names)
    grad = np.zeros(n)
    for S in sc.sets:
        keep = [j for j in range(n) if j not in S]
        U, s, Vt = np.linalg.svd(J[:, keep], full_matrices=False)
        if singular == "skip" and not s[-1] > s[0] / RCN_SINGULAR:  # no term (eq. S1)
            continue
        smax, smin = s[0], max(s[-1], s[0] / RCN_MAX)
        dS = dJ[:, :, keep]  # (n, m, n_keep)
        dmax = np.einsum("i,jik,k->j", U[:, 0], dS, Vt[0])
        dmin = np.einsum("i,jik,k->j", U[:, -1], dS, Vt[-1])
        k = smax / smin
        grad += 2.0 * k * (dmax * smin - smax * dmin) / smin**2
    return grad


def fault_tolerance_measure(J: np.ndarray, lockable=None) -> float:
    """``k_f = min_S σ_min(J_S)`` (Roberts & Maciejewski): worst-case reduced dexterity."""
    J = finite(J, "J", ndim=2)
    return float(reduced_singular_values(J, _scenarios(J, lockable))[:, 0].min())


def reduced_manipulability(J: np.ndarray, lockable=None) -> np.ndarray:
    """``w_S = √det(J_S J_Sᵀ)`` per scenario, shape (f,)."""
    J = finite(J, "J", ndim=2)
    return np.prod(reduced_singular_values(J, _scenarios(J, lockable)), axis=1)
