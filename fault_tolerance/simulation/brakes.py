"""The lock as a brake: an ideal impulse, or a finite brake torque; the dynamics of a held joint.

Ideal brake, docs/MATH.md (D5): the locked joints ``S`` stop at once. The velocity jump ``Δq̇`` and
the brake's impulse ``λ`` [N·m·s] solve the KKT system of an impulsive joint constraint

    [M  Eᵀ] [Δq̇]   [ 0       ]
    [E  0 ] [ λ ] = [−E q̇⁻    ]        (E selects the rows S)

so ``M Δq̇ = −Eᵀλ`` (the generalised impulse acts on the locked joints only) and ``E(q̇⁻ + Δq̇) = 0``.
In closed form ``λ = (E M⁻¹ Eᵀ)⁻¹ E q̇⁻`` and the kinetic energy changes by ``−½ λᵀ E M⁻¹ Eᵀ λ``.
We solve it directly with NumPy (Pinocchio's ``impulseDynamics`` takes contact models of frames,
not joint constraints); the tests check ``M Δq̇ = −Eᵀλ`` against Pinocchio's ``M(q)``.

Finite brake (D6): the joint decelerates under ``τ_S = −B sign(q̇_S)`` until it stops, then holds.
A held joint moves the reduced dynamics ``M[K, K] q̈_K = τ_K − h_K``, ``q̈_S = 0`` (D7).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class BrakeImpulse(NamedTuple):
    """The ideal brake's result at one instant."""

    qd: np.ndarray  # rates after the lock [rad/s], shape (n,)
    dqd: np.ndarray  # Δq̇ [rad/s], shape (n,)
    impulse: np.ndarray  # λ [N·m·s] on the locked joints, shape (|S|,)
    energy_jump: float  # ½q̇⁺ᵀMq̇⁺ − ½q̇⁻ᵀMq̇⁻ [J], never positive


# Eqn. (D5)
def ideal_brake(M: np.ndarray, qd: np.ndarray, locked) -> BrakeImpulse:
    """Rates after an ideal brake stops joints ``locked`` at once (the KKT system above)."""
    n = len(qd)
    S = np.atleast_1d(np.asarray(locked, dtype=int))
    E = np.zeros((len(S), n))
    E[np.arange(len(S)), S] = 1.0
    kkt = np.block([[M, E.T], [E, np.zeros((len(S), len(S)))]])
    rhs = np.concatenate([np.zeros(n), -E @ qd])
    sol = np.linalg.solve(kkt, rhs)
    dqd, lam = sol[:n], sol[n:]
    after = qd + dqd
    after[S] = 0.0  # exactly
    energy = 0.5 * after @ M @ after - 0.5 * qd @ M @ qd
    return BrakeImpulse(after, dqd, lam, float(energy))


# Eqn. (D7)
def held_accelerations(M: np.ndarray, h: np.ndarray, tau: np.ndarray, keep: np.ndarray):
    """``q̈`` with the joints outside ``keep`` held: ``M[K,K] q̈_K = τ_K − h_K``, others 0."""
    qdd = np.zeros(len(tau))
    qdd[keep] = np.linalg.solve(M[np.ix_(keep, keep)], tau[keep] - h[keep])
    return qdd


def check_brake_torque(value) -> float | None:
    """A finite brake torque > 0 [N·m], or None (the ideal brake); else :class:`InvalidInput`."""
    from fault_tolerance.errors import InvalidInput

    if value is None:
        return None
    b = float(value)
    if not (np.isfinite(b) and b > 0):
        raise InvalidInput(
            f"brake torque must be a finite torque > 0 [N·m] (omit it for the ideal brake), got {value}"
        )
    return b
