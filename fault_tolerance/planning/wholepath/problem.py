"""The whole-path problem as data, batched kinematics and the exact rollout (MATH.md (W1)-(W3)).

A :class:`PathProblem` samples the task path at ``t_k = k·dt`` (k = 0..T), holds the failure
scenarios, the joint limits and the objective. :func:`rollout` integrates rates the way
:func:`~fault_tolerance.simulation.simulate.simulate` does (explicit Euler, the same task feedback), so every
trajectory it returns satisfies ``J q̇_k = ẋ_cmd,k`` at every step by construction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.arm import Arm
from fault_tolerance.numerics.linalg import damped_pivots, projection, reduced_rates
from fault_tolerance.planning.posture_steps import pinv_and_null
from fault_tolerance.resolution.indices import condition_numbers, reduced_singular_values
from fault_tolerance.resolution.jvja import jvja_rates
from fault_tolerance.resolution.scenarios import Scenarios, scenarios

#: Objectives of the whole-path planner: the mean or the maximum of λ(t) over the path.
OBJECTIVES = ("mean", "max")


@dataclass(frozen=True)
class PathProblem:
    """One whole-path planning problem (T + 1 samples, n joints, m task rows, f scenarios)."""

    arm: Arm
    sc: Scenarios
    dt: float
    x_des: np.ndarray  # (T+1, m)
    xd_des: np.ndarray  # (T+1, m)
    feedback_gain: float
    lower: np.ndarray  # (n,) position limits, -inf where none is enforced
    upper: np.ndarray  # (n,)
    vmax: np.ndarray  # (n,) velocity limits [rad/s], inf where none is enforced
    rcn_max: float | None = None
    objective: str = "mean"

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise InvalidInput(f"objective {self.objective!r} is not one of {list(OBJECTIVES)}")
        if self.rcn_max is not None and not (np.isfinite(self.rcn_max) and self.rcn_max >= 1):
            raise InvalidInput(f"rcn_max must be a finite number >= 1, got {self.rcn_max}")

    @property
    def T(self) -> int:
        """Number of steps (the plan has T + 1 samples)."""
        return len(self.x_des) - 1

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.arm.n

    def score(self, lam: np.ndarray) -> float:
        """The objective of a jump history λ(t): its mean or its maximum."""
        return float(np.mean(lam) if self.objective == "mean" else np.max(lam))


def build_problem(
    arm: Arm,
    path,
    *,
    dt: float,
    steps: int,
    lockable=None,
    weights=None,
    feedback_gain: float = 0.0,
    limits: bool = True,
    rcn_max: float | None = None,
    objective: str = "mean",
) -> PathProblem:
    """Sample ``path`` at ``k·dt`` (k = 0..steps) and collect limits and scenarios.

    ``limits=True`` enforces the URDF's position and velocity limits, as the bounded resolvers do
    (:func:`fault_tolerance.resolution.limits.velocity_limits`: defaults where the URDF gives none).
    """
    sc = scenarios(
        arm.default_lockable if lockable is None else lockable,
        arm.n,
        r=arm.redundancy,
        weights=weights,
        joint_names=arm.joint_names,
    )
    t = np.arange(steps + 1) * dt
    x_des = np.array([path.x(tk) for tk in t], dtype=float)
    xd_des = np.array([path.xdot(tk) for tk in t], dtype=float)
    if not (np.all(np.isfinite(x_des)) and np.all(np.isfinite(xd_des))):
        raise InvalidInput("the path gives non-finite positions or velocities")
    n = arm.n
    lo, hi, vmax = np.full(n, -np.inf), np.full(n, np.inf), np.full(n, np.inf)
    if limits:  # the same limits as the bounded resolvers (fault_tolerance.resolution.limits)
        from fault_tolerance.model.joint_limits import NO_LIMIT, velocity_limits

        lo = np.where(np.abs(arm.lower) < NO_LIMIT, arm.lower, -np.inf)
        hi = np.where(np.abs(arm.upper) < NO_LIMIT, arm.upper, np.inf)
        vmax = velocity_limits(arm)
    return PathProblem(
        arm, sc, dt, x_des, xd_des, float(feedback_gain), lo, hi, vmax, rcn_max, objective
    )


# -- batched kinematics ---------------------------------------------------------------------


def kinematics(prob: PathProblem, Q: np.ndarray, ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Task Jacobians (B, m, n) and task errors ``x_des[k] − x(q)`` (B, m) at rows of ``Q``.

    The same error as :meth:`Arm.task_error`, batched: linear rows subtract; with all three angular
    rows the error is ``log3(R_des Rᵀ)``, with some of them their rotation-vector components subtract.
    """
    arm = prob.arm
    model, data, fid, rows = arm.model, arm.data, arm.frame_id, arm.rows
    B, n = len(Q), arm.n
    J = np.empty((B, 6, n))
    M = np.empty((B, 3, 4))
    frame, lwa = pin.computeFrameJacobian, pin.LOCAL_WORLD_ALIGNED
    oMf = data.oMf
    for b, q in enumerate(Q):  # the placement as one 4 x 4 array (one conversion, not two)
        J[b] = frame(model, data, q, fid, lwa).reshape(6, n)
        M[b] = oMf[fid].homogeneous[:3]
    full = np.zeros((B, 6))
    full[:, rows] = prob.x_des[ks]
    err = np.zeros((B, 6))
    err[:, :3] = full[:, :3] - M[:, :, 3]
    ang = rows[rows >= 3]
    if len(ang):
        from scipy.spatial.transform import Rotation  # here: scipy.spatial takes 0.25 s to import
    if len(ang) == 3:
        Rd = Rotation.from_rotvec(full[:, 3:]).as_matrix()
        err[:, 3:] = Rotation.from_matrix(Rd @ np.swapaxes(M[:, :, :3], 1, 2)).as_rotvec()
    elif len(ang):
        err[:, 3:] = full[:, 3:] - Rotation.from_matrix(M[:, :, :3]).as_rotvec()
    return J[:, rows], err[:, rows]


# Eqn. (2) in closed form (G1), batched, pivots damped as in simulate.
def post_rates(a: np.ndarray, N: np.ndarray, sc: Scenarios) -> np.ndarray:
    """Least-norm post-failure rates ``ˢq̇'`` for every scenario, shape (B, f, n).

    :func:`~fault_tolerance.numerics.linalg.reduced_rates` on the stack, pivots damped as in
    :func:`~fault_tolerance.simulation.simulate.simulate` after its first step.
    """
    return np.stack([reduced_rates(a, N, S, damp=True) for S in sc.sets], axis=1)


def jumps(post: np.ndarray, qd: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Square-sum jump (9)/(10), ``λ = Σ_S w_S ‖ˢq̇' − q̇‖²``, shape (B,)."""
    d = post - qd[:, None, :]
    return np.einsum("f,bfn,bfn->b", w, d, d)


def reduced_condition_numbers(J: np.ndarray, sc: Scenarios) -> np.ndarray:
    """Reduced condition numbers (15) ``k_S``, shape (B, f): :func:`ft.rcn` on the stack."""
    return condition_numbers(reduced_singular_values(J, sc))


# -- trajectories ---------------------------------------------------------------------------


class Trajectory(NamedTuple):
    """A rolled-out plan: configurations and rates at t_k (T+1 rows) and what they cost."""

    q: np.ndarray  # (T+1, n) [rad]
    qd: np.ndarray  # (T+1, n) [rad/s], J(q_k) qd_k = xd_cmd_k
    lam: np.ndarray  # (T+1,) square-sum jump
    violation: float  # largest limit violation (position [rad], velocity [rad/s], RCN)
    score: float  # the objective


def rollout(
    prob: PathProblem, q0: np.ndarray, mode: str = "jvja", q_ref: np.ndarray | None = None
) -> Trajectory:
    """Integrate the rates of ``mode`` from ``q0``: ``"lnva"``, ``"jvja"`` or ``"track"``.

    ``"track"`` follows the reference ``q_ref`` (T+1 rows) in the null space:
    ``q̇_k = J⁺ẋ_cmd + N (q_ref[k+1] − q_k)/dt`` (the last step takes JVJA's rates), so the task
    constraint holds exactly whatever the reference (MATH.md (W3)).
    """
    if mode not in ("lnva", "jvja", "track"):
        raise InvalidInput(f"rollout mode {mode!r} is not one of ['lnva', 'jvja', 'track']")
    if mode == "track" and q_ref is None:
        raise InvalidInput("rollout mode 'track' needs q_ref, the reference (T+1, n)")
    T, n, dt = prob.T, prob.n, prob.dt
    arm = prob.arm
    model, data, fid, rows = arm.model, arm.data, arm.frame_id, arm.rows
    Q = np.empty((T + 1, n))
    QD = np.empty((T + 1, n))
    q = np.asarray(q0, dtype=float).copy()
    sc, eye = prob.sc, np.eye(n)
    for k in range(T + 1):
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED).reshape(6, n)
        xd = prob.xd_des[k]
        if prob.feedback_gain:
            xd = xd + prob.feedback_gain * arm._error(prob.x_des[k], data.oMf[fid])
        Jpinv, N = pinv_and_null(J[rows], eye, mode != "lnva")
        a = Jpinv @ xd
        if mode == "lnva":
            qd = a
        elif mode == "track" and q_ref is not None and k < T:
            qd = a + N @ ((q_ref[k + 1] - q) / dt)
        else:
            qd = jvja_rates(a, N, sc, damped_pivots(sc.pivots(N)), damp=True)  # (5), as simulate
        Q[k], QD[k] = q, qd
        q = q + dt * qd
    return evaluate(prob, Q, QD)


def evaluate(prob: PathProblem, Q: np.ndarray, QD: np.ndarray) -> Trajectory:
    """Jumps, limit violation and objective of configurations ``Q`` with rates ``QD``."""
    ks = np.arange(len(Q))
    J, E = kinematics(prob, Q, ks)
    P = projection(J)
    a = np.einsum("bnm,bm->bn", P.Jpinv, prob.xd_des + prob.feedback_gain * E)
    lam = jumps(post_rates(a, P.N, prob.sc), QD, prob.sc.weights)
    return Trajectory(Q, QD, lam, violation(prob, Q, QD, J), prob.score(lam))


def violation(prob: PathProblem, Q: np.ndarray, QD: np.ndarray, J: np.ndarray) -> float:
    """Largest violation of the position, velocity and (optional) RCN limits; 0 when feasible."""
    v = max(
        float(np.max(np.maximum(prob.lower - Q, Q - prob.upper), initial=0.0)),
        float(np.max(np.abs(QD) - prob.vmax, initial=0.0)),
        0.0,
    )
    if prob.rcn_max is not None:
        v = max(v, float(np.max(reduced_condition_numbers(J, prob.sc) - prob.rcn_max)))
    return v


def feasible(traj: Trajectory, tol: float = 1e-9) -> bool:
    """True when the trajectory keeps every limit (within ``tol``)."""
    return traj.violation <= tol


__all__ = [
    "OBJECTIVES",
    "PathProblem",
    "Trajectory",
    "build_problem",
    "evaluate",
    "feasible",
    "jumps",
    "kinematics",
    "post_rates",
    "reduced_condition_numbers",
    "rollout",
]
