r"""JVJA in the arm's inertia metric: the minimum kinetic-energy jump, docs/MATH.md (D1)-(D4).

When joints ``S`` lock, the reduced robot's rates nearest to ``q̇`` in the inertia metric that keep
the task are ``q̇ + Δ_S``, ``Δ_S = argmin ½ΔᵀMΔ`` subject to ``JΔ = 0``, ``Δ[S] = −q̇[S]`` (D1).
Its kinetic energy is ``½ q̇[S]ᵀ Ñ[S, S]⁻¹ q̇[S]`` with
``Ñ = M⁻¹ − M⁻¹Jᵀ(JM⁻¹Jᵀ)⁻¹JM⁻¹`` (D2). The rates that minimise ``Σ_S w_S`` of it subject to
``Jq̇ = ẋ`` are ``q̇ = a + Nz``, ``z = −(N H N)⁺ N H a``, ``H = Σ_S w_S E_S Ñ[S, S]⁻¹ E_Sᵀ`` (D3):
the continuation form (G3) with ``N[S, S]`` replaced by ``Ñ[S, S]``. With ``M = I`` it is (G3).

For one degree of redundancy the jump of every scenario is forced (``Δ_S ∥ n``) and its kinetic
energy is ``½ nᵀMn`` times the square jump: the same minimiser as JVJA (D4).

Registered as ``"jvja_inertia"`` (:mod:`fault_tolerance.resolution.resolvers`); it needs the
configuration (``arm`` and ``q``, or the inertia ``M`` directly). Its options
(:class:`JvjaInertiaOptions`): the scenario ``weights``. Its bounded variant
:func:`bounded_jvja_inertia` is (L2) with the metric of (D3).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import Projection, pivot_block, projection
from fault_tolerance.resolution.bounded import (
    BoundedRates,
    _continuation,
    _inside,
    reduced_under_limits,
)
from fault_tolerance.resolution.scenarios import Scenarios, scenarios


@dataclass(frozen=True)
class JvjaInertiaOptions:
    """jvja_inertia's options: the scenario ``weights`` (default 1 each).

    The inertia is not an option: it is the configuration's, ``M`` or ``arm`` and ``q`` (context).
    """

    weights: Sequence[float] | None = None


def _scenarios(J: np.ndarray, lockable, weights, joint_names) -> Scenarios:
    m, n = J.shape
    return scenarios(lockable, n, r=n - m, weights=weights, joint_names=joint_names)


def check_inertia(M, n: int) -> np.ndarray:
    """``M`` as a finite symmetric positive definite (n, n) array, or :class:`InvalidInput`."""
    M = np.asarray(M, dtype=float)
    if M.shape != (n, n) or not np.all(np.isfinite(M)):
        raise InvalidInput(f"M must be a finite ({n}, {n}) inertia matrix, got shape {M.shape}")
    M = 0.5 * (M + M.T)
    if np.linalg.eigvalsh(M).min() <= 0:
        raise InvalidInput("M must be positive definite (the arm's joint-space inertia M(q))")
    return M


# Eqn. (D2)
def inertia_projector(J: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``Ñ = M⁻¹ − M⁻¹Jᵀ(JM⁻¹Jᵀ)⁻¹JM⁻¹`` (D2), shape (n, n), symmetric, ``JÑ = 0``."""
    Minv = np.linalg.inv(M)
    B = J @ Minv  # (m, n)
    G = B @ J.T
    Nt = Minv - B.T @ np.linalg.solve(G, B)
    return 0.5 * (Nt + Nt.T)


# Eqn. (D3): the metric of the kinetic-energy jump
def kinetic_jump_metric(J: np.ndarray, M: np.ndarray, sc: Scenarios, tolerate: bool = False):
    """``H = Σ_S w_S E_S Ñ[S, S]⁻¹ E_Sᵀ`` (D3), shape (n, n): the jump energy is ``½ q̇ᵀHq̇``."""
    Nt = inertia_projector(J, M)
    scale = float(np.trace(M)) / len(M)  # [kg·m²]: scale · Ñ is dimensionless, like N
    H = np.zeros_like(Nt)
    for S, w in zip(sc.sets, sc.weights / sc.weights.max(), strict=True):
        block = pivot_block(scale * Nt, S, tolerate)  # damped like N[S, S] when tolerated
        H[np.ix_(S, S)] += w * scale * np.linalg.inv(block)
    return H


# Eqn. (D1)-(D2): the kinetic energy each scenario's jump carries
def kinetic_jumps(J, qd, M, lockable=None, *, weights=None, joint_names=()) -> np.ndarray:
    """``w_S · ½ q̇[S]ᵀ Ñ[S, S]⁻¹ q̇[S]`` [J] per scenario, shape (f,)."""
    J = np.asarray(J, dtype=float)
    sc = _scenarios(J, lockable, weights, joint_names)
    M = check_inertia(M, J.shape[1])
    Nt = inertia_projector(J, M)
    qd = np.asarray(qd, dtype=float)
    out = [0.5 * qd[list(S)] @ np.linalg.solve(Nt[np.ix_(S, S)], qd[list(S)]) for S in sc.sets]
    return sc.weights * np.array(out)


#: The dynamics of each arm jvja_inertia was asked to weigh by its own inertia (built once).
_DYNAMICS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _inertia(M, arm, q, n: int) -> np.ndarray:
    if M is not None:
        return check_inertia(M, n)
    if arm is None or q is None:
        raise InvalidInput(
            "jvja_inertia needs the inertia: pass M=... (the arm's M(q)) or arm=... and q=..."
        )
    from fault_tolerance.model.dynamics import ArmDynamics

    dyn = _DYNAMICS.get(arm)
    if dyn is None:
        dyn = _DYNAMICS[arm] = ArmDynamics(arm)
    return check_inertia(dyn.mass_matrix(np.asarray(q, dtype=float)), n)


# Eqn. (D3)
def jvja_inertia(
    J: np.ndarray,
    xdot: np.ndarray,
    lockable=None,
    *,
    M: np.ndarray | None = None,
    arm=None,
    q: np.ndarray | None = None,
    weights: Sequence[float] | None = None,
    joint_names: Sequence[str] = (),
    tolerate: bool = False,
    proj: Projection | None = None,
) -> np.ndarray:
    r"""Inertia-weighted JVJA: minimum square-sum kinetic-energy jump (D3).

    :math:`\dot q = a + N z`, :math:`z = -(NHN)^+ NHa`, :math:`H = \sum_S w_S E_S
    \tilde N_{S,S}^{-1} E_S^T`, :math:`\tilde N = M^{-1} - M^{-1}J^T(JM^{-1}J^T)^{-1}JM^{-1}`.

    Args:
        J: Task Jacobian, shape (m, n).
        xdot: Task velocity, shape (m,).
        lockable: Joints that may lock (as :func:`~fault_tolerance.resolve`).
        M: Joint-space inertia at the configuration [kg·m²], shape (n, n); or give ``arm`` and
            ``q`` and it comes from the arm's description (:class:`~.dynamics.ArmDynamics`).
        arm: The arm (for ``M``, and lockable joints by name).
        q: The configuration (with ``arm``).
        weights: Scenario weights (default 1).
        joint_names: Names of the columns (to name lockable joints).
        tolerate: Damp the pivots of ``Ñ[S, S]`` instead of raising (the simulation does).
        proj: The :func:`~.linalg.projection` of ``J`` when the caller has it.

    Raises:
        IntolerableFailure: a scenario's ``N[S, S]`` is singular (so is ``Ñ[S, S]``), unless
            ``tolerate``.
    """
    J = np.asarray(J, dtype=float)
    sc = _scenarios(J, lockable, weights, joint_names)
    proj = proj or projection(J)
    if not tolerate:
        sc.check_tolerable(proj.N)
    Mq = _inertia(M, arm, q, J.shape[1])
    H = kinetic_jump_metric(J, Mq, sc, tolerate)
    N, a = proj.N, proj.Jpinv @ xdot
    z = -np.linalg.pinv(N @ H @ N, rcond=1e-10, hermitian=True) @ (N @ H @ a)
    return a + N @ z


# Eqn. (L2) with the kinetic-energy metric H of (D3).
def bounded_jvja_inertia(
    J, xdot, lockable, lo, hi, *, M=None, arm=None, q=None, weights=None, joint_names=(),
    tolerate=False, proj=None,
) -> BoundedRates:  # fmt: skip
    """jvja_inertia inside the box ``[lo, hi]``: ``min ½q̇ᵀHq̇`` s.t. ``J q̇ = s ẋ``, (L2) with (D3)'s H.

    Inside the box the unbounded rates come back unchanged; ``reduced_scale`` is each scenario's
    task scale under the same box (as JVJA's).
    """
    J = np.asarray(J, dtype=float)
    proj = proj or projection(J)
    sc = _scenarios(J, lockable, weights, joint_names)
    Mq = _inertia(M, arm, q, J.shape[1])
    qd = jvja_inertia(J, xdot, sc, M=Mq, tolerate=tolerate, proj=proj)  # the unbounded optimum
    _, scales = reduced_under_limits(J, xdot, sc, lo, hi, proj=proj, tolerate=tolerate)
    if _inside(qd, lo, hi):
        return BoundedRates(np.clip(qd, lo, hi), 1.0, np.zeros(len(qd), dtype=bool), scales)
    H = kinetic_jump_metric(J, Mq, sc, tolerate)
    sol = _continuation(J, xdot, sc, lo, hi, proj, tolerate, H=H)
    return BoundedRates(sol.qd, sol.scale, sol.active, scales)
