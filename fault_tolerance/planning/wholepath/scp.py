"""Sequential convex programming over the whole path, any redundancy (MATH.md (W5)).

Around a nominal trajectory ``(q̄_k, q̄̇_k)`` the rates are written ``q̇_k = a(q_k) + N(q_k) B̄_k v_k``
(``B̄_k`` an orthonormal null-space basis at ``q̄_k``, ``v_k ∈ Rʳ``). Linearising the dynamics
``q_{k+1} = q_k + dt q̇_k`` and the residuals ``√w_S (ˢq̇'(q_k) − q̇_k)`` (derivatives by forward
differences, batched over the path) gives a sparse QP in ``(δq, δv)``: Gauss-Newton model of the mean
jump (or the linearised maximum), the joint position and velocity limits, the optional RCN bound,
and a box trust region. OSQP solves it; the candidate is then rolled out exactly (null-space
tracking of the predicted states, :func:`~.problem.rollout`) and kept only if it is feasible and
better. The best feasible iterate is returned, so the result is never worse than the warm start.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    import scipy.sparse as sp

from fault_tolerance.errors import InvalidInput
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.planning.wholepath.problem import (
    PathProblem,
    Trajectory,
    kinematics,
    post_rates,
    reduced_condition_numbers,
    rollout,
)

#: Forward-difference step for the derivatives in q [rad].
FD_STEP = 1e-6
#: Slack kept from the limits in the QP (position [rad], velocity as a fraction of the limit).
POS_MARGIN = 2e-3
VEL_MARGIN = 1e-3
#: Iterations OSQP may take on one QP with active limits (the step is then shortened instead).
#: A count, not a time: a wall-clock limit made the plan depend on the machine's load.
OSQP_MAX_ITER = 4000
#: SCP stops when an accepted step improves the objective by less than this (relative).
SCP_RTOL = 1e-4
#: SCP stops after this many rejected steps in a row (each one shortens the step tenfold).
MAX_REJECTED = 5
#: Exponents of the max objective's surrogate (W6): the first, and the last of the doublings.
P_START, P_MAX = 32.0, 1024.0


class SCPResult(NamedTuple):
    """The best feasible iterate and how the optimisation went."""

    best: Trajectory
    start: Trajectory  # the warm start it improved on
    iterations: int
    accepted: int
    history: list  # objective after every accepted step


class _Linear(NamedTuple):
    D: np.ndarray  # (K, n, n) ∂q̇/∂q at fixed v
    Bn: np.ndarray  # (K, n, r) null basis
    A: np.ndarray  # (K, f·n, n) ∂R/∂q
    C: np.ndarray  # (K, f·n, r) ∂R/∂v
    R: np.ndarray  # (K, f·n) residuals
    dk: np.ndarray | None  # (K, f, n) ∂k_S/∂q
    k: np.ndarray | None  # (K, f) RCN at q̄


def _rates_and_residuals(prob, Q, ks, Bn, v):
    J, E = kinematics(prob, Q, ks)
    P = projection(J)
    a = np.einsum("bnm,bm->bn", P.Jpinv, prob.xd_des[ks] + prob.feedback_gain * E)
    qd = a + np.einsum("bij,bj->bi", P.N, np.einsum("bnr,br->bn", Bn, v))
    sw = np.sqrt(prob.sc.weights)[None, :, None]
    R = sw * (post_rates(a, P.N, prob.sc) - qd[:, None, :])
    return qd, R.reshape(len(Q), -1), J


def linearise(prob: PathProblem, traj: Trajectory) -> _Linear:
    """Batched forward-difference linearisation of rates, residuals and RCN along ``traj``."""
    K, n = traj.q.shape
    ks = np.arange(K)
    J0, _ = kinematics(prob, traj.q, ks)
    r = prob.arm.redundancy
    Bn = np.swapaxes(np.linalg.svd(J0, full_matrices=True)[2][:, prob.arm.m :, :], 1, 2)
    v = np.einsum("bnr,bn->br", Bn, traj.qd)
    qd0, R0, _ = _rates_and_residuals(prob, traj.q, ks, Bn, v)
    Qp = (traj.q[:, None, :] + FD_STEP * np.eye(n)[None]).reshape(K * n, n)
    rep = np.repeat(ks, n)
    qdp, Rp, Jp = _rates_and_residuals(prob, Qp, rep, np.repeat(Bn, n, 0), np.repeat(v, n, 0))
    D = np.swapaxes((qdp.reshape(K, n, n) - qd0[:, None]) / FD_STEP, 1, 2)
    A = np.swapaxes((Rp.reshape(K, n, -1) - R0[:, None]) / FD_STEP, 1, 2)
    sw = np.sqrt(prob.sc.weights)
    C = -(sw[None, :, None, None] * Bn[:, None]).reshape(K, -1, r)
    dk = k = None
    if prob.rcn_max is not None:
        k = reduced_condition_numbers(J0, prob.sc)
        kp = reduced_condition_numbers(Jp, prob.sc).reshape(K, n, -1)
        dk = np.swapaxes((kp - k[:, None]) / FD_STEP, 1, 2)
    return _Linear(D, Bn, A, C, R0, dk, k)


def _coo(blocks: np.ndarray, r0: np.ndarray, c0: np.ndarray):
    """COO triplets of dense blocks (K, a, b) placed at row/column offsets (K,)."""
    K, a, b = blocks.shape
    rows = r0[:, None, None] + np.arange(a)[None, :, None] + 0 * np.arange(b)[None, None, :]
    cols = c0[:, None, None] + np.arange(b)[None, None, :] + 0 * np.arange(a)[None, :, None]
    return rows.ravel(), cols.ravel(), blocks.ravel()


class QP(NamedTuple):
    """``min ½xᵀPx + cᵀx`` s.t. ``A_eq x = b_eq``, ``l ≤ A_in x ≤ u`` (sparse)."""

    P: sp.csc_matrix
    c: np.ndarray
    Aeq: sp.csc_matrix
    beq: np.ndarray
    Ain: sp.csc_matrix | None
    lin: np.ndarray
    uin: np.ndarray
    nq: int


class _Rows:
    """Accumulates sparse constraint rows with their bounds."""

    def __init__(self) -> None:
        self.r: list[np.ndarray] = []
        self.c: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.lo: list[np.ndarray] = []
        self.hi: list[np.ndarray] = []
        self.m = 0

    def add(self, rr, cc, vv, lo, hi) -> None:
        self.r.append(rr + self.m)
        self.c.append(cc)
        self.v.append(vv)
        self.lo.append(lo)
        self.hi.append(hi)
        self.m += len(lo)

    def matrix(self, nx: int):
        if not self.m:
            return None, np.zeros(0), np.zeros(0)
        import scipy.sparse as sp  # here: scipy.sparse costs 0.1 s to import

        A = sp.csc_matrix(
            (np.concatenate(self.v), (np.concatenate(self.r), np.concatenate(self.c))),
            shape=(self.m, nx),
        )
        return A, np.concatenate(self.lo), np.concatenate(self.hi)


def _placed(blocks, starts_per_col):
    """COO of blocks (K, a, b) whose column ranges are the concatenation of ``starts_per_col``."""
    K, a, b = blocks.shape
    rr, cc, vv = _coo(blocks, np.arange(K) * a, np.zeros(K, int))
    cmap = np.concatenate([s[:, None] + np.arange(w)[None, :] for s, w in starts_per_col], axis=1)
    k = np.repeat(np.arange(K), a * b)
    return rr, cmap[k, cc], vv


# MATH.md (W6): the smooth surrogate of the maximum.
def sample_weights(lam: np.ndarray, objective: str, p: float, L: float):
    """First and second derivatives ``(φ'(λ_k), φ''(λ_k))`` of the per-sample cost, shape (K,) each.

    Mean: ``φ(λ) = λ/K``. Max: ``φ(λ) = (L/p)(λ/L)^p``, whose sum is a smooth stand-in for the
    maximum (its p-th root tends to ``max λ`` as p grows; ``L`` is a fixed scale near it).
    """
    K = len(lam)
    if objective == "mean":
        return np.full(K, 1.0 / K), np.zeros(K)
    s = np.maximum(lam, 0.0) / L
    with np.errstate(over="ignore"):  # a sample far above L: inf, and the step is refused
        return s ** (p - 1), (p - 1) / L * s ** (p - 2)


def surrogate(lam: np.ndarray, objective: str, p: float, L: float) -> float:
    """The cost the QP models: mean of λ, or ``Σ (L/p)(λ_k/L)^p`` for the maximum (W6)."""
    if objective == "mean":
        return float(np.mean(lam))
    with np.errstate(over="ignore"):
        return float(L / p * np.sum((np.maximum(lam, 0.0) / L) ** p))


def build_qp(
    prob: PathProblem,
    traj: Trajectory,
    lin: _Linear,
    mu: float,
    fixed_start: bool,
    p: float = 1.0,
    L: float = 1.0,
) -> QP:
    """The sparse QP in ``x = (δq, δv[, u])``, proximal weight ``mu`` on ``δv``.

    The objective is the Gauss-Newton model of ``Σ_k φ(λ_k)`` (:func:`sample_weights`): per
    sample ``φ'·2Hₖ + φ''·4gₖgₖᵀ`` and ``φ'·2gₖ`` with ``Hₖ = GₖᵀGₖ``, ``gₖ = GₖᵀRₖ``.
    """
    import scipy.sparse as sp  # here: scipy.sparse costs 0.1 s to import

    K, n = traj.q.shape
    r = lin.Bn.shape[2]
    dt, T = prob.dt, K - 1
    nq, nv = K * n, K * r
    iu = nq + nv
    nx = iu + (0 if fixed_start else r)
    kq, kv = np.arange(K) * n, nq + np.arange(K) * r
    AC = np.concatenate([lin.A, lin.C], axis=2)  # (K, f·n, n+r)
    H = np.einsum("kai,kaj->kij", AC, AC)
    g = np.einsum("kai,ka->ki", AC, lin.R)
    d1, d2 = sample_weights(np.einsum("ka,ka->k", lin.R, lin.R), prob.objective, p, L)
    Hs = 2 * d1[:, None, None] * H + 4 * d2[:, None, None] * np.einsum("ki,kj->kij", g, g)
    idx = np.concatenate([kq[:, None] + np.arange(n), kv[:, None] + np.arange(r)], axis=1)
    c = np.zeros(nx)
    diag = np.full(nx, 1e-9 / K)
    diag[nq:nx] = mu / K
    Pr = np.broadcast_to(idx[:, :, None], Hs.shape).ravel()
    Pc = np.broadcast_to(idx[:, None, :], Hs.shape).ravel()
    P = sp.coo_matrix((Hs.ravel(), (Pr, Pc)), shape=(nx, nx))
    np.add.at(c, idx.ravel(), (2 * d1[:, None] * g).ravel())
    P = (P + sp.diags(diag)).tocsc()
    eq = _Rows()
    # dynamics δq_{k+1} − (I + dt D_k) δq_k − dt B̄_k δv_k = 0
    blocks = np.concatenate(
        [-(np.eye(n) + dt * lin.D[:T]), -dt * lin.Bn[:T], np.broadcast_to(np.eye(n), (T, n, n))],
        axis=2,
    )
    rr, cc, vv = _placed(blocks, [(kq[:T], n), (kv[:T], r), (kq[1:], n)])
    eq.add(rr, cc, vv, np.zeros(T * n), np.zeros(T * n))
    # the start: fixed, or moved along the self-motion of x0 (δq_0 = B̄_0 u)
    rr, cc, vv = np.arange(n), np.arange(n), np.ones(n)
    if not fixed_start:
        r2, c2, v2 = _placed(-lin.Bn[:1], [(np.array([iu]), r)])
        rr, cc, vv = np.r_[rr, r2], np.r_[cc, c2], np.r_[vv, v2]
    eq.add(rr, cc, vv, np.zeros(n), np.zeros(n))
    Aeq, beq, _ = eq.matrix(nx)
    ineq = _Rows()
    if np.any(np.isfinite(prob.vmax)):  # linearised rates within the limits (relaxed to q̄̇)
        vlim, qd = prob.vmax * (1 - VEL_MARGIN), traj.qd
        blocks = np.concatenate([lin.D, lin.Bn], axis=2)
        rr, cc, vv = _placed(blocks, [(kq, n), (kv, r)])
        ineq.add(
            rr, cc, vv, (np.minimum(-vlim, qd) - qd).ravel(), (np.maximum(vlim, qd) - qd).ravel()
        )
    bounded = np.flatnonzero(np.isfinite(prob.lower) | np.isfinite(prob.upper))
    if len(bounded):  # positions within the limits (relaxed to q̄)
        q = traj.q[:, bounded]
        lo = np.minimum(prob.lower[bounded] + POS_MARGIN - q, 0.0)
        hi = np.maximum(prob.upper[bounded] - POS_MARGIN - q, 0.0)
        cols = (kq[:, None] + bounded[None, :]).ravel()
        ineq.add(np.arange(len(cols)), cols, np.ones(len(cols)), lo.ravel(), hi.ravel())
    if lin.dk is not None and lin.k is not None and prob.rcn_max is not None:  # set together
        f = lin.k.shape[1]
        rr, cc, vv = _placed(lin.dk, [(kq, n)])
        ineq.add(
            rr, cc, vv, np.full(K * f, -np.inf), (np.maximum(prob.rcn_max, lin.k) - lin.k).ravel()
        )
    Ain, lin_, uin = ineq.matrix(nx)
    return QP(P, c, Aeq.tocsc(), beq, Ain, lin_, uin, nq)


def _kkt(P, c, Aeq, beq) -> np.ndarray:
    """Minimiser of ½xᵀPx + cᵀx on ``Aeq x = beq`` from one sparse LU of the KKT matrix."""
    import scipy.sparse as sp  # here: scipy.sparse costs 0.1 s to import
    from scipy.sparse.linalg import spsolve

    nx, me = P.shape[0], Aeq.shape[0]
    KKT = sp.bmat([[P, Aeq.T], [Aeq, -1e-12 * sp.eye(me)]], format="csc")
    return spsolve(KKT, np.concatenate([-c, beq]))[:nx]


def _violated(qp: QP, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = qp.Ain @ x
    return z < qp.lin - 1e-9, z > qp.uin + 1e-9


def solve_qp(qp: QP, rounds: int = 6) -> np.ndarray | None:
    """Solve the QP; ``None`` when nothing does.

    The equality-constrained KKT system by sparse LU; where its solution breaks inequalities,
    those rows are held at their bounds and the system solved again (a few rounds of an
    active-set guess); OSQP (warm-started) when that does not settle. The candidate is checked on
    its exact rollout anyway, so a feasible point suffices.
    """
    import scipy.sparse as sp  # here: scipy.sparse costs 0.1 s to import

    x = _kkt(qp.P, qp.c, qp.Aeq, qp.beq)
    if not np.all(np.isfinite(x)):
        return None
    if qp.Ain is None:
        return x
    active = np.zeros(qp.Ain.shape[0], bool)
    bound = np.zeros(qp.Ain.shape[0])
    for _ in range(rounds):
        lo, hi = _violated(qp, x)
        if not (lo.any() or hi.any()):
            return x
        bound = np.where(lo, qp.lin, np.where(hi, qp.uin, bound))
        active |= lo | hi
        A = sp.vstack([qp.Aeq, qp.Ain[active]], format="csc")
        x = _kkt(qp.P, qp.c, A, np.concatenate([qp.beq, bound[active]]))
        if not np.all(np.isfinite(x)):
            break
    import osqp

    A = sp.vstack([qp.Aeq, qp.Ain], format="csc")
    solver = osqp.OSQP()
    solver.setup(
        sp.triu(qp.P, format="csc"),
        qp.c,
        A,
        np.concatenate([qp.beq, qp.lin]),
        np.concatenate([qp.beq, qp.uin]),
        verbose=False,
        eps_abs=1e-5,
        eps_rel=1e-5,
        max_iter=OSQP_MAX_ITER,
        polishing=True,
    )
    if np.all(np.isfinite(x)):
        solver.warm_start(x=x)
    res = solver.solve(raise_error=False)
    status = str(res.info.status).lower()
    if "solved" not in status or "unsolved" in status or res.x is None:
        return None
    return np.asarray(res.x)


def _better(new: Trajectory, cur: Trajectory, tol: float, values=None) -> bool:
    """Feasibility first (violation not above max(tol, current)), then the objective.

    ``values``: ``(new, current)`` of the cost to compare instead of the trajectories' scores.
    """
    if new.violation > max(tol, cur.violation) + 1e-12:
        return False
    if cur.violation > tol and new.violation < cur.violation - 1e-12:
        return True
    a, b = (new.score, cur.score) if values is None else values
    return a < b - 1e-12 * max(1.0, abs(b))


class _Stage:
    """The surrogate's exponent p and scale L (max objective; p = 1 for the mean) (W6)."""

    def __init__(self, prob: PathProblem, cur: Trajectory) -> None:
        self.objective = prob.objective
        self.p = 1.0 if self.objective == "mean" else P_START
        self.reset(cur)

    def reset(self, cur: Trajectory) -> None:
        self.L = max(float(np.max(cur.lam)), 1e-300)
        self.value = self.of(cur)

    def of(self, traj: Trajectory) -> float:
        return surrogate(traj.lam, self.objective, self.p, self.L)

    def sharpen(self, cur: Trajectory) -> bool:
        """Double p (max objective) and rescale; False when there is nothing left to sharpen."""
        if self.objective == "mean" or self.p >= P_MAX:
            return False
        self.p *= 2
        self.reset(cur)
        return True


def scp(
    prob: PathProblem,
    warm: Trajectory,
    *,
    fixed_start: bool = True,
    iterations: int = 15,
    mu: float | None = None,
    tol: float = 1e-9,
    progress=None,
) -> SCPResult:
    """Improve ``warm`` (a rolled-out trajectory) by sequential convex programming.

    Never returns anything worse than ``warm``: a step is kept only when its exact rollout keeps
    the limits and lowers the modelled cost (the mean, or the surrogate (W6) of the maximum,
    whose exponent doubles each time the steps stall); the best feasible iterate on the objective
    itself is returned.
    """
    W = float(prob.sc.weights.sum())
    mu0 = 0.1 * W if mu is None else float(mu)
    if not (np.isfinite(mu0) and mu0 > 0):
        raise InvalidInput(f"proximal weight mu must be > 0, got {mu0}")
    mu = mu0
    cur = best = warm
    stage = _Stage(prob, cur)
    history = [warm.score]
    accepted = rejected = 0
    it = 0
    for it in range(1, iterations + 1):  # noqa: B007 - the count is returned below
        new = _step(prob, cur, mu, fixed_start, stage)
        value = None if new is None else stage.of(new)
        if new is not None and value is not None and _better(new, cur, tol, (value, stage.value)):
            gain = (stage.value - value) / max(abs(stage.value), 1e-300)
            cur, stage.value = new, value
            best = cur if _better(cur, best, tol) else best
            accepted += 1
            rejected = 0
            history.append(cur.score)
            mu = max(mu * 0.3, 1e-6 * W)
            stalled = 0 <= gain < SCP_RTOL
        else:
            mu *= 10.0
            rejected += 1
            stalled = mu > 1e6 * W or rejected >= MAX_REJECTED
        if stalled:
            if not stage.sharpen(cur):
                break
            mu, rejected = mu0, 0
        if progress is not None:
            progress.update(1)
    return SCPResult(best, warm, it, accepted, history)


def _step(prob, cur: Trajectory, mu: float, fixed_start: bool, stage: _Stage):
    """One SCP candidate from ``cur`` (its exact rollout), or None when the QP fails."""
    lin = linearise(prob, cur)
    qp = build_qp(prob, cur, lin, mu, fixed_start, stage.p, stage.L)
    x = solve_qp(qp)
    if x is None:
        return None
    dq = x[: qp.nq].reshape(cur.q.shape)
    dq[0] = 0.0 if fixed_start else dq[0]  # a fixed start is kept bit for bit
    q0 = cur.q[0] + dq[0]
    if not fixed_start:
        from fault_tolerance.planning.wholepath.dp import _correct

        q0 = _correct(prob, q0[None], np.array([0]), iters=4)[0]
    return rollout(prob, q0, "track", q_ref=cur.q + dq)
