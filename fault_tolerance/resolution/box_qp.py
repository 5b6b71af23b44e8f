"""The small QP behind every bounded resolver: nearest rates on the task's affine set inside a box.

Every bounded resolver (:mod:`fault_tolerance.resolution.bounded`) solves, for its own target ``c`` and metric
``H`` (identity, or the continuation response's jump metric),

    (L2)   min ½ (q̇ − c)ᵀ H (q̇ − c)   s.t.   J q̇ = s ẋ,   q̇_lo ≤ q̇ ≤ q̇_hi,

with the largest task scaling ``s ≤ 1`` for which the set is not empty (L3). On the affine set
``q̇ = x₀(s) + M u`` (``x₀(s) = p₀ + s d`` the unbounded optimum, ``M = Z L⁻ᵀ`` with ``Z`` an
orthonormal null-space basis and ``ZᵀHZ = LLᵀ``) the objective is ``½‖u‖²`` plus a constant, so
(L2) is the nearest point to the origin of the polytope ``lo − x₀ ≤ M u ≤ hi − x₀`` in ``R^r``.
:func:`nearest_point` finds it exactly with the dual active-set method of Goldfarb & Idnani (the
method inside quadprog), which starts from the unbounded optimum ``u = 0`` and adds one violated
bound at a time: with no bound violated the unbounded rates come back untouched; every further
bound costs one small solve. When it stops on an empty set it returns a Farkas certificate: a
non-negative combination of bounds whose right-hand side, affine in ``s``, must be ≤ 0; its root
is an upper bound of the task scaling (L3). Solving again at that ``s`` either succeeds (then that
``s`` is the largest: every feasible ``s`` lies below every certificate's root) or gives a smaller
root; a few rounds find the exact largest ``s`` without a linear-programming solver.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InfeasibleBounds

#: Feasibility tolerance of a bound [rad/s]: a rate within it of its bound counts as inside.
BOX_TOL = 1e-12
#: Rows of M with a norm below this do not move in the null space (the bound is on x₀ alone).
ROW_EPS = 1e-12


class BoxSolution(NamedTuple):
    """Solution of (L2)/(L3): the rates, the task scaling and the joints held at a bound."""

    qd: np.ndarray  # (n,) rates inside the box, J q̇ = s ẋ
    scale: float  # s in [0, 1]; 1 when ẋ itself is reachable inside the box
    active: np.ndarray  # (n,) bool: the joint's bound is in the optimal active set
    iterations: int  # active-set changes (0: the unbounded optimum was inside the box)


class Certificate(NamedTuple):
    """Farkas certificate of an empty polytope: ``Σ coef_k e_k > 0`` for rows ``rows``."""

    rows: np.ndarray  # indices into the constraint rows
    coef: np.ndarray  # non-negative coefficients


def _constraints(M: np.ndarray, blo: np.ndarray, bhi: np.ndarray):
    """Rows ``nₖᵀu ≥ eₖ`` of ``blo ≤ M u ≤ bhi`` (finite bounds only), their joint and side (±1)."""
    up = np.flatnonzero(np.isfinite(bhi))
    dn = np.flatnonzero(np.isfinite(blo))
    Nk = np.vstack([-M[up], M[dn]])
    e = np.concatenate([-bhi[up], blo[dn]])
    joint = np.concatenate([up, dn])
    side = np.concatenate([np.ones(len(up)), -np.ones(len(dn))])
    return Nk, e, joint, side


def _step_direction(NA: np.ndarray, npv: np.ndarray):
    """``rr`` with ``N_A rr`` the part of ``n_p`` in the active rows' span; ``z = n_p − N_A rr``.

    By a QR factor of ``N_A`` (r, k), not its normal equations: near-dependent active rows (nearly
    parallel bounds in the null space) keep ``z`` accurate to rounding instead of to the square of
    their condition number. With ``k = r`` rows ``n_p`` is in their span and ``z = 0`` exactly.
    """
    r, k = NA.shape
    if k == 0:
        return np.zeros(0), npv
    Q, R = np.linalg.qr(NA)
    rr = np.linalg.solve(R, Q.T @ npv)
    z = np.zeros(r) if k >= r else npv - Q @ (Q.T @ npv)
    return rr, z


# Goldfarb & Idnani (1983), dual active set, with Hessian I: min ½‖u‖² s.t. nₖᵀu ≥ eₖ.
def nearest_point(Nk: np.ndarray, e: np.ndarray):
    """Point of ``{u : Nk u ≥ e}`` nearest the origin: ``(u, active rows, iterations)``.

    Or a :class:`Certificate` when the set is empty. Exact up to rounding: each iteration either
    adds a violated row with a full step or drops one whose multiplier reached zero.
    """
    r = Nk.shape[1]
    u = np.zeros(r)
    norms = np.sqrt(np.einsum("kr,kr->k", Nk, Nk))
    flat = np.flatnonzero((norms < ROW_EPS) & (e > BOX_TOL))
    if len(flat):  # a bound that no null-space motion can meet
        return Certificate(flat[:1], np.ones(1))
    moving = norms >= ROW_EPS
    safe = np.where(moving, norms, 1.0)
    A: list[int] = []
    mu = np.zeros(0)
    it = 0
    limit = 10 * (len(e) + 1)
    while True:
        viol = np.where(moving, (Nk @ u - e) / safe, 0.0)
        if len(viol) == 0 or viol.min() >= -BOX_TOL:
            return u, np.array(A, dtype=int), it
        p = int(np.argmin(viol))
        mu_p = 0.0
        while True:
            it += 1
            if it > limit:  # pragma: no cover - GI terminates; guard against rounding loops
                raise InfeasibleBounds("the bounded rates did not converge (active-set cycling)")
            npv = Nk[p]
            rr, z = _step_direction(Nk[A].T, npv)
            pos = rr > 1e-14
            t1, k = np.inf, -1
            if np.any(pos):
                ratios = np.where(pos, mu / np.where(pos, rr, 1.0), np.inf)
                k = int(np.argmin(ratios))
                t1 = float(ratios[k])
            zz = float(z @ z)
            sp = float(npv @ u - e[p])
            t2 = -sp / zz if zz > 1e-14 * float(npv @ npv) else np.inf  # else n_p ∈ span(N_A)
            t = min(t1, t2)
            if not np.isfinite(t):  # n_p = N_A rr with rr ≤ 0: e_p − Σ rr_j e_j ≤ 0 is needed
                return Certificate(np.array([p, *A], dtype=int), np.concatenate([[1.0], -rr]))
            if np.isfinite(t2):
                u = u + t * z
            mu = mu - t * rr
            mu_p += t
            if t2 <= t1:  # full step: row p joins the active set
                A.append(p)
                mu = np.append(mu, mu_p)
                break
            del A[k]  # partial step: the multiplier of row k reached zero
            mu = np.delete(mu, k)


#: Rounds of (L3): a certificate's root, then a solve there (a handful suffice in practice).
MAX_SCALE_ROUNDS = 50


def solve_box(p0, d, M, lo, hi) -> BoxSolution:
    """(L2) with (L3): rates ``p₀ + s d + M u`` inside ``[lo, hi]``, ``s`` as large as possible.

    ``p₀ + d`` is the unbounded optimum at ``s = 1``, ``M`` (n, r) the metric-scaled null-space
    basis. Returns the unbounded optimum itself when it is inside the box. Raises
    :class:`InfeasibleBounds` when no ``s ∈ [0, 1]`` is reachable.
    """
    n = len(p0)
    Nk, e_lo_hi, joint, side = _constraints(M, lo, hi)  # rows for x = 0; shifted below
    e0 = e_lo_hi + side * p0[joint]  # e_k(s) = e0_k + s e1_k (upper: x − hi, lower: lo − x)
    e1 = side * d[joint]
    s = 1.0
    for _ in range(MAX_SCALE_ROUNDS):
        x = p0 + s * d
        if s == 1.0 and np.all(x >= lo - BOX_TOL) and np.all(x <= hi + BOX_TOL):
            return BoxSolution(np.clip(x, lo, hi), 1.0, np.zeros(n, dtype=bool), 0)
        found = nearest_point(Nk, e0 + s * e1)
        if not isinstance(found, Certificate):
            u, rows, it = found
            qd = np.clip(x + M @ u, lo, hi)
            active = np.zeros(n, dtype=bool)
            active[joint[rows]] = True
            if s < 1.0:  # at the scaled optimum more joints may sit on a bound, multiplier 0
                active |= (qd <= lo + BOX_TOL) | (qd >= hi - BOX_TOL)
            return BoxSolution(qd, s, active, it)
        g0 = float(found.coef @ e0[found.rows])
        g1 = float(found.coef @ e1[found.rows])
        if not g1 > 0 or -g0 / g1 < -1e-12:  # lowering s does not help, or not even s = 0
            raise InfeasibleBounds(
                "no joint rates inside the rate box reach any fraction of the task velocity, "
                "not even zero (is the configuration outside its joint limits?)"
            )
        s_new = max(-g0 / g1, 0.0)
        s = s_new if s_new < s else s * (1.0 - 1e-12) - 1e-15  # rounding at a touching point
    raise InfeasibleBounds("the task scaling did not converge")  # pragma: no cover
