"""Planar chains read from Pinocchio, and the closed-form reach of a 2R sub-chain with limits.

An arm is a *planar chain* for the task ``(x, y)`` when every active joint is revolute about an
axis parallel to the world z axis. Pinocchio's placements at ``q = 0`` then give everything: the
base point ``p0`` (origin of the first joint), the link lengths ``l_i`` (distance between the
origins of joints i and i+1, the last one to the tip frame; rigid, so the same at every ``q``),
the link directions ``c_i`` at ``q = 0`` and the axis signs ``s_i = ±1``. With the shifted joint
variables ``v_k = s_k q_k + d_k`` (``d_1 = c_1``, ``d_k = c_k − c_{k−1}``) link i points along
``α_i = v_1 + … + v_i`` and the tip is ``p0 + Σ l_i e(α_i)``, ``e(α) = (cos α, sin α)``.
:func:`planar_chain` checks this model against Pinocchio's forward kinematics before it is used.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import InvalidInput

#: A joint whose range spans 2π up to this [rad] counts as a full turn (URDF ±3.14159 does).
FULL_TURN_TOL = 1e-4
TWO_PI = 2.0 * np.pi


class PlanarChain(NamedTuple):
    """A planar nR chain in shifted joint variables (module doc)."""

    p0: np.ndarray  # base point [m], shape (2,)
    lengths: np.ndarray  # l_i [m], shape (n,)
    offsets: np.ndarray  # d_k [rad], shape (n,): v_k = s_k q_k + d_k
    signs: np.ndarray  # s_k = ±1, shape (n,)

    def v_limits(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Limits of ``v`` from limits of ``q`` (a reversed axis swaps and negates them)."""
        a = np.where(self.signs > 0, lo, -hi) + self.offsets
        b = np.where(self.signs > 0, hi, -lo) + self.offsets
        return a, b

    def q_of_v(self, v: np.ndarray) -> np.ndarray:
        """Joint positions ``q_k = s_k (v_k − d_k)`` of shifted variables (last axis n)."""
        return self.signs * (v - self.offsets)

    def tip(self, v: np.ndarray) -> np.ndarray:
        """Tip position of shifted variables ``v`` (..., n), shape (..., 2)."""
        alpha = np.cumsum(v, axis=-1)
        return self.p0 + np.stack([np.cos(alpha) @ self.lengths, np.sin(alpha) @ self.lengths], -1)


def planar_chain(arm, checks: int = 8, tol: float = 1e-9) -> PlanarChain | None:
    """The :class:`PlanarChain` of ``arm``, or ``None`` when it is not one (module doc)."""
    if tuple(arm.task) != ("x", "y"):
        return None
    model, data = arm.model, arm.data
    rng = np.random.default_rng(0)
    for k in range(checks):
        q = arm.neutral() if k == 0 else arm.random_q(rng)
        pin.computeJointJacobians(model, data, q)
        Jw = pin.getFrameJacobian(model, data, arm.frame_id, pin.WORLD).reshape(6, arm.n)
        w = Jw[3:]
        if not (np.allclose(w[:2], 0.0, atol=tol) and np.allclose(np.abs(w[2]), 1.0, atol=tol)):
            return None
    q0 = np.zeros(arm.n)
    pin.framesForwardKinematics(model, data, q0)
    origins = [data.oMi[j].translation[:2].copy() for j in range(1, model.njoints)]
    origins.append(data.oMf[arm.frame_id].translation[:2].copy())
    vec = np.diff(np.array(origins), axis=0)
    lengths = np.linalg.norm(vec, axis=1)
    c = np.arctan2(vec[:, 1], vec[:, 0])
    pin.computeJointJacobians(model, data, q0)
    Jw = pin.getFrameJacobian(model, data, arm.frame_id, pin.WORLD).reshape(6, arm.n)
    signs = np.sign(Jw[5])
    offsets = np.diff(np.concatenate([[0.0], c]))
    chain = PlanarChain(origins[0], lengths, offsets, signs)
    for _ in range(checks):
        q = arm.random_q(rng)
        v = signs * q + offsets
        if not np.allclose(chain.tip(v), arm.fk(q), atol=1e-9):
            return None
    return chain


def require_planar_chain(arm) -> PlanarChain:
    """The :class:`PlanarChain` of ``arm``, or :class:`InvalidInput` when it is not one."""
    chain = planar_chain(arm)
    if chain is None:
        raise InvalidInput(
            f"{arm.name} is not a planar chain (revolute joints about parallel z axes, task x/y); "
            f"its task is {'/'.join(arm.task)}"
        )
    return chain


def in_interval(angle, lo, hi) -> np.ndarray:
    """``angle`` (mod 2π) lies in ``[lo, hi]``; always true when the interval is a full turn."""
    span = hi - lo
    rel = np.mod(np.asarray(angle) - lo, TWO_PI)
    return (span >= TWO_PI - FULL_TURN_TOL) | (rel <= span + 1e-12) | (rel >= TWO_PI - 1e-12)


def full_turn(lo, hi) -> np.ndarray:
    """The range ``[lo, hi]`` is a full turn (up to :data:`FULL_TURN_TOL`)."""
    return np.asarray(hi) - np.asarray(lo) >= TWO_PI - FULL_TURN_TOL


def cos_range(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest ``cos u`` over ``u ∈ [lo, hi]`` (exact: ends and interior extrema)."""
    lo, hi = np.broadcast_arrays(np.asarray(lo, float), np.asarray(hi, float))
    ends_max = np.maximum(np.cos(lo), np.cos(hi))
    ends_min = np.minimum(np.cos(lo), np.cos(hi))
    full = full_turn(lo, hi)
    has0 = full | (np.ceil(lo / TWO_PI) * TWO_PI <= hi)
    hasp = full | (np.ceil((lo - np.pi) / TWO_PI) * TWO_PI + np.pi <= hi)
    return np.where(hasp, -1.0, ends_min), np.where(has0, 1.0, ends_max)


class Reach2R(NamedTuple):
    """Closed-form 2R inverse kinematics of many points: membership and both branches."""

    hit: np.ndarray  # reachable within the limits, shape (P,)
    ok: np.ndarray  # per branch (elbow +/-) within the limits, shape (2, P)
    va: np.ndarray  # absolute angle of the first link per branch [rad], shape (2, P)
    vb: np.ndarray  # relative angle of the second link per branch [rad], shape (2, P)


def reach_2r(d, L1, L2, a_lo, a_hi, b_lo, b_hi) -> Reach2R:
    r"""Points ``d`` (P, 2) relative to the base reached by a 2R chain with limits.

    The first link (length ``L1``) points along ``va ∈ [a_lo, a_hi]``, the second (``L2``) along
    ``va + vb`` with ``vb ∈ [b_lo, b_hi]``. :math:`\cos v_b = (\rho^2 - L_1^2 - L_2^2)/(2L_1L_2)`
    has the two branches ``±acos``; then :math:`v_a = \varphi - \mathrm{atan2}(L_2\sin v_b,
    L_1 + L_2\cos v_b)`. Exact (no sampling); all arguments broadcast over the P points.
    """
    r2 = d[:, 0] ** 2 + d[:, 1] ** 2
    den = 2.0 * L1 * L2
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (r2 - L1**2 - L2**2) / np.where(den > 0, den, np.nan)
    real = np.abs(c) <= 1.0 + 1e-12
    beta = np.arccos(np.clip(np.nan_to_num(c, nan=2.0), -1.0, 1.0))
    phi = np.arctan2(d[:, 1], d[:, 0])
    vb = np.stack([beta, -beta])
    va = phi - np.arctan2(L2 * np.sin(vb), L1 + L2 * np.cos(vb))
    ok = real & in_interval(vb, b_lo, b_hi) & in_interval(va, a_lo, a_hi)
    return Reach2R(ok[0] | ok[1], ok, va, vb)


def rigid_pair(la: float, lb: float, theta):
    """Length and direction of ``la e(0) + lb e(θ)``: two links with the joint between locked."""
    z = la + lb * np.exp(1j * np.asarray(theta, dtype=float))
    return np.abs(z), np.angle(z)
