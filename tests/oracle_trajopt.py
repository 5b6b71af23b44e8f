"""An independent trajectory optimiser: the oracle the whole-path planner is checked against.

It shares nothing with :mod:`fault_tolerance.planning.wholepath` but the problem's data (the arm,
the sampled path, the scenario weights and the limits of a ``PathProblem``): its own rollout, its
own jump, its own parametrisation and scipy's optimisers.

Parametrisation (one degree of redundancy, as in every paper case): the rates are
``q̇_k = J_k⁺ ẋ_k + n(q_k) ν(t_k)`` with ``n`` the unit null vector of ``J`` signed by its cofactors
(``n_i ∝ (−1)ⁱ det J_{:,−i}``, so it turns continuously along the path) and ``ν`` a clamped cubic
B-spline (``knots`` control points); ``J_k q̇_k = ẋ_k`` holds at every sample by construction. The arm integrates ``q_{k+1} = q_k + dt q̇_k`` from the fixed start. The jump
is ``λ_k = Σ_S w_S ‖J_{S,k}⁺ ẋ_k − q̇_k‖²`` with ``J_S`` the Jacobian with the columns of ``S``
zeroed (the least-norm post-failure rates, computed directly, not by the (G1) closed form). The
objective is the mean of λ (L-BFGS-B) or its maximum (SLSQP on the epigraph ``λ_k ≤ τ``); joint
position and velocity limits enter as a quadratic penalty (zero inside the limits), and the
result reports its largest violation. Gradients are forward differences, all perturbed
rollouts integrated together (one batch). Task feedback is not modelled (``feedback_gain`` 0).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin
from scipy.interpolate import BSpline
from scipy.optimize import minimize


class OracleResult(NamedTuple):
    """The oracle's best trajectory and its (own) objective."""

    score: float  # mean or max of λ on the oracle's own rollout
    q: np.ndarray  # (T+1, n)
    qd: np.ndarray  # (T+1, n)
    lam: np.ndarray  # (T+1,)
    violation: float  # largest position [rad] / velocity [rad/s] limit violation
    evaluations: int


def _basis(T: int, dt: float, knots: int) -> np.ndarray:
    """Clamped cubic B-spline design matrix, shape (T+1, knots)."""
    t = np.arange(T + 1) * dt
    inner = np.linspace(0.0, t[-1], knots - 2)
    k = np.r_[[0.0] * 3, inner, [t[-1]] * 3]
    return BSpline.design_matrix(np.clip(t, 0.0, t[-1]), k, 3).toarray()


def _pinv(J: np.ndarray) -> np.ndarray:
    """``Jᵀ (J Jᵀ)⁻¹`` for a stack of full-row-rank Jacobians (B, m, n)."""
    return np.swapaxes(J, 1, 2) @ np.linalg.inv(J @ np.swapaxes(J, 1, 2))


def null_vector(J: np.ndarray) -> np.ndarray:
    """Unit null vectors of a stack of (B, n−1, n) Jacobians, signed by the cofactors of ``J``."""
    n = J.shape[2]
    c = np.stack([(-1) ** i * np.linalg.det(np.delete(J, i, axis=2)) for i in range(n)], axis=1)
    return c / np.linalg.norm(c, axis=1, keepdims=True)


class _Rollout:
    """Batched rollouts of many control-point sets at once."""

    def __init__(self, prob, q0: np.ndarray, knots: int) -> None:
        if prob.feedback_gain:
            raise ValueError("the oracle models no task feedback (feedback_gain must be 0)")
        if prob.arm.redundancy != 1:
            raise ValueError("the oracle parametrises one degree of redundancy (r = 1)")
        self.prob, self.q0 = prob, np.asarray(q0, float)
        self.arm = prob.arm
        self.n, self.T, self.dt = self.arm.n, prob.T, prob.dt
        self.Bm = _basis(self.T, self.dt, knots)
        self.sets = [list(S) for S in prob.sc.sets]
        self.w = np.asarray(prob.sc.weights, float)
        self.evaluations = 0

    def run(self, C: np.ndarray):
        """Rollouts for control points C (P, knots): q, qd (P, T+1, n), λ (P, T+1)."""
        arm, n, dt = self.arm, self.n, self.dt
        model, data, fid, rows = arm.model, arm.data, arm.frame_id, arm.rows
        V = C @ self.Bm.T  # (P, T+1) null speeds
        P = len(C)
        self.evaluations += P
        Q = np.empty((P, self.T + 1, n))
        QD = np.empty_like(Q)
        lam = np.empty((P, self.T + 1))
        q = np.repeat(self.q0[None], P, axis=0)
        for k in range(self.T + 1):
            J = np.stack(
                [pin.computeFrameJacobian(model, data, qb, fid, pin.LOCAL_WORLD_ALIGNED)[rows]
                 for qb in q]
            )  # fmt: skip
            xd = self.prob.xd_des[k]
            qd = _pinv(J) @ xd + null_vector(J) * V[:, k, None]  # J qd = xd
            tot = np.zeros(P)
            for wS, S in zip(self.w, self.sets, strict=True):
                JS = J.copy()
                JS[:, :, S] = 0.0
                d = _pinv(JS) @ xd - qd
                tot += wS * np.einsum("pi,pi->p", d, d)
            Q[:, k], QD[:, k], lam[:, k] = q, qd, tot
            q = q + dt * qd
        return Q, QD, lam

    def violation(self, Q: np.ndarray, QD: np.ndarray) -> np.ndarray:
        """Per-sample limit violations (P, T+1, 2n), zero inside the limits."""
        p = self.prob
        pos = np.maximum(p.lower - Q, 0.0) + np.maximum(Q - p.upper, 0.0)
        vel = np.maximum(np.abs(QD) - p.vmax, 0.0)
        return np.concatenate([np.nan_to_num(pos), np.nan_to_num(vel)], axis=2)


def _fd(ro: _Rollout, x: np.ndarray, shape, h: float):
    """Rollout at ``x`` and at ``x + h e_j`` for every j, as one batch."""
    X = np.vstack([x, x[None] + h * np.eye(len(x))])
    return ro.run(X.reshape((len(X), *shape)))


def optimise(
    prob,
    q0: np.ndarray,
    *,
    knots: int = 16,
    penalty: float = 1e4,
    maxiter: int = 300,
    h: float = 1e-6,
    seeds: tuple[str, ...] = ("lnva", "jvja"),
) -> OracleResult:
    """Minimise the problem's objective (``prob.objective``) over the spline, from each seed.

    Seeds: ``"lnva"`` (ν ≡ 0) and ``"jvja"`` (the spline fitted to the null speed of the oracle's
    own JVJA run: the weighted mean of the post-failure rates). Returns the best converged result.
    """
    ro = _Rollout(prob, q0, knots)
    shape = (knots,)
    starts = [np.zeros(knots)]
    if "jvja" in seeds:
        starts.append(_jvja_seed(ro).ravel())
    best = None
    for x0 in starts[(0 if "lnva" in seeds else 1) :]:
        res = (
            _mean(ro, x0, shape, penalty, maxiter, h)
            if prob.objective == "mean"
            else _max(ro, x0, shape, penalty, maxiter, h)
        )
        if best is None or (res.violation > 2e-4, res.score) < (best.violation > 2e-4, best.score):
            best = res
    assert best is not None
    return best._replace(evaluations=ro.evaluations)


def _jvja_seed(ro: _Rollout) -> np.ndarray:
    """Control points of the least-squares spline through the oracle's own JVJA null speed."""
    arm = ro.arm
    model, data, fid, rows = arm.model, arm.data, arm.frame_id, arm.rows
    q = ro.q0.copy()
    nu = np.empty(ro.T + 1)
    for k in range(ro.T + 1):
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)[rows][None]
        xd = ro.prob.xd_des[k]
        post = []
        for S in ro.sets:
            JS = J.copy()
            JS[:, :, S] = 0.0
            post.append((_pinv(JS) @ xd)[0])
        qdj = np.einsum("s,sn->n", ro.w, np.array(post)) / ro.w.sum()
        nu[k] = float(null_vector(J)[0] @ qdj)
        q = q + ro.dt * qdj
    return np.linalg.lstsq(ro.Bm, nu, rcond=None)[0]


def _pen(ro: _Rollout, Q, QD, penalty: float) -> np.ndarray:
    v = ro.violation(Q, QD)
    return penalty * np.einsum("ptj,ptj->p", v, v)


def _mean(ro, x0, shape, penalty, maxiter, h) -> OracleResult:
    def fg(x):
        Q, QD, lam = _fd(ro, x, shape, h)
        f = lam.mean(axis=1) + _pen(ro, Q, QD, penalty)
        return f[0], (f[1:] - f[0]) / h

    res = minimize(fg, x0, jac=True, method="L-BFGS-B",
                   options={"maxiter": maxiter, "ftol": 1e-12, "gtol": 1e-9})  # fmt: skip
    return _result(ro, res.x, shape)


def _max(ro, x0, shape, penalty, maxiter, h) -> OracleResult:
    nv = len(x0)
    cache: dict = {}

    def roll(x):
        key = x[:nv].tobytes()
        if key not in cache:
            cache.clear()
            Q, QD, lam = _fd(ro, x[:nv], shape, h)
            pen = _pen(ro, Q, QD, penalty)
            cache[key] = lam + pen[:, None]
        return cache[key]

    def cons(x):  # τ − λ_k ≥ 0
        return x[nv] - roll(x)[0]

    def cons_jac(x):
        L = roll(x)
        G = (L[1:] - L[0][None]) / h  # (nv, T+1)
        return np.hstack([-G.T, np.ones((G.shape[1], 1))])

    lam0 = ro.run(x0.reshape((1, *shape)))[2][0]
    z0 = np.r_[x0, lam0.max()]
    res = minimize(
        lambda z: z[nv],
        z0,
        jac=lambda z: np.r_[np.zeros(nv), 1.0],
        method="SLSQP",
        constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
        options={"maxiter": maxiter, "ftol": 1e-12},
    )
    return _result(ro, res.x[:nv], shape)


def _result(ro: _Rollout, x: np.ndarray, shape) -> OracleResult:
    Q, QD, lam = ro.run(x.reshape((1, *shape)))
    score = float(lam[0].mean() if ro.prob.objective == "mean" else lam[0].max())
    viol = float(ro.violation(Q, QD).max(initial=0.0))
    return OracleResult(score, Q[0], QD[0], lam[0], viol, ro.evaluations)
