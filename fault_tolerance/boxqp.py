"""The small QP behind every bounded resolver: nearest rates on the task's affine set inside a box.

Every bounded resolver (:mod:`fault_tolerance.bounded`) solves, for its own target ``c`` and metric
``H`` (identity, or the continuation response's jump metric),

    (L2)   min ½ (q̇ − c)ᵀ H (q̇ − c)   s.t.   J q̇ = s ẋ,   q̇_lo ≤ q̇ ≤ q̇_hi,

with the largest task scaling ``s ≤ 1`` for which the set is not empty (L3). On the affine set
``q̇ = x₀(s) + M u`` (``x₀(s) = p₀ + s d`` the unbounded optimum, ``M = Z L⁻ᵀ`` with ``Z`` an
orthonormal null-space basis and ``ZᵀHZ = LLᵀ``) the objective is ``½‖u‖²`` plus a constant, so
(L2) is the nearest point to the origin of the polytope ``lo − x₀ ≤ M u ≤ hi − x₀`` in ``R^r``.
:func:`nearest_point` finds it exactly with the dual active-set method of Goldfarb & Idnani (the
method inside quadprog), which starts from the unbounded optimum ``u = 0`` and adds one violated
bound at a time: with no bound violated the unbounded rates come back untouched; every further
bound costs one small solve. Infeasibility is certain when it stops; then (L3) is a linear
programme in ``(u, s)`` (scipy's HiGHS), solved only on that rare path.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .errors import InfeasibleBounds

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


def _constraints(M: np.ndarray, blo: np.ndarray, bhi: np.ndarray):
    """Rows ``nᵢᵀu ≥ eᵢ`` of ``blo ≤ M u ≤ bhi`` (finite bounds only) and the joint of each row."""
    rows, rhs, joint = [], [], []
    for i in range(M.shape[0]):
        if np.isfinite(bhi[i]):
            rows.append(-M[i])
            rhs.append(-bhi[i])
            joint.append(i)
        if np.isfinite(blo[i]):
            rows.append(M[i])
            rhs.append(blo[i])
            joint.append(i)
    r = M.shape[1]
    Nk = np.array(rows, dtype=float).reshape(len(rows), r)
    return Nk, np.array(rhs, dtype=float), np.array(joint, dtype=int)


# Goldfarb & Idnani (1983), dual active set, with Hessian I: min ½‖u‖² s.t. nₖᵀu ≥ eₖ.
def nearest_point(M: np.ndarray, blo: np.ndarray, bhi: np.ndarray):
    """Point of ``{u : blo ≤ M u ≤ bhi}`` nearest the origin, or ``None`` when the set is empty.

    Returns ``(u, active_joints, iterations)``. Exact up to rounding: each iteration either adds
    a violated bound with a full step or drops one whose multiplier reached zero.
    """
    Nk, e, joint = _constraints(M, blo, bhi)
    r = M.shape[1]
    u = np.zeros(r)
    norms = np.linalg.norm(Nk, axis=1) if len(e) else np.zeros(0)
    if np.any((norms < ROW_EPS) & (e > BOX_TOL)):
        return None  # a bound that no null-space motion can meet
    moving = norms >= ROW_EPS
    A: list[int] = []
    mu = np.zeros(0)
    it = 0
    limit = 10 * (len(e) + 1)
    while True:
        slack = Nk @ u - e
        viol = np.where(moving, slack / np.where(moving, norms, 1.0), 0.0)
        if len(viol) == 0 or viol.min() >= -BOX_TOL:
            return u, joint[A], it
        p = int(np.argmin(viol))
        mu_p = 0.0
        while True:
            it += 1
            if it > limit:  # pragma: no cover - GI terminates; guard against rounding loops
                raise InfeasibleBounds("the bounded rates did not converge (active-set cycling)")
            npv = Nk[p]
            if A:
                NA = Nk[A].T  # (r, k)
                rr = np.linalg.solve(NA.T @ NA, NA.T @ npv)
                z = npv - NA @ rr
            else:
                rr = np.zeros(0)
                z = npv
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
            if not np.isfinite(t):
                return None  # the violated bound is incompatible with the active ones
            if np.isfinite(t2):
                u = u + t * z
            mu = mu - t * rr
            mu_p += t
            if t2 <= t1:  # full step: bound p joins the active set
                A.append(p)
                mu = np.append(mu, mu_p)
                break
            del A[k]  # partial step: the multiplier of bound k reached zero
            mu = np.delete(mu, k)
            if sp + t * zz >= -BOX_TOL * norms[p]:
                break


def largest_scale(p0: np.ndarray, d: np.ndarray, M: np.ndarray, lo, hi) -> tuple[float, np.ndarray]:
    """(L3) The largest ``s ∈ [0, 1]`` with ``lo ≤ p₀ + s d + M u ≤ hi`` for some ``u``; and that ``u``.

    A linear programme in ``(u, s)`` (scipy's HiGHS). Raises :class:`InfeasibleBounds` when no
    ``s ∈ [0, 1]`` is feasible (the box excludes even the rates that hold the task still).
    """
    from scipy.optimize import linprog

    n, r = M.shape
    hi_rows = np.isfinite(hi)
    lo_rows = np.isfinite(lo)
    A = np.vstack(
        [np.hstack([M, d[:, None]])[hi_rows], -np.hstack([M, d[:, None]])[lo_rows]]
    ).reshape(-1, r + 1)
    b = np.concatenate([(hi - p0)[hi_rows], (p0 - lo)[lo_rows]])
    cost = np.zeros(r + 1)
    cost[-1] = -1.0
    res = linprog(
        cost, A_ub=A, b_ub=b, bounds=[(None, None)] * r + [(0.0, 1.0)], method="highs",
        options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
    )
    if res.status != 0:
        raise InfeasibleBounds(
            "no joint rates inside the rate box reach any fraction of the task velocity, not even "
            "zero (is the configuration outside its joint limits?)"
        )
    return float(res.x[-1]), np.asarray(res.x[:-1])


def solve_box(p0, d, M, lo, hi) -> BoxSolution:
    """(L2) with (L3): rates ``p₀ + s d + M u`` inside ``[lo, hi]``, ``s`` as large as possible.

    ``p₀ + d`` is the unbounded optimum at ``s = 1``, ``M`` (n, r) the metric-scaled null-space
    basis. Returns the unbounded optimum itself when it is inside the box.
    """
    x = p0 + d
    if np.all(x >= lo - BOX_TOL) and np.all(x <= hi + BOX_TOL):
        return BoxSolution(np.clip(x, lo, hi), 1.0, np.zeros(len(x), dtype=bool), 0)
    found = nearest_point(M, lo - x, hi - x)
    s = 1.0
    if found is None:
        s, u_lp = largest_scale(p0, d, M, lo, hi)
        for shrink in (0.0, 1e-12, 1e-10, 1e-8):
            x = p0 + s * (1.0 - shrink) * d
            found = nearest_point(M, lo - x, hi - x)
            if found is not None:
                s *= 1.0 - shrink
                break
        else:  # rounding at a degenerate vertex: the LP's point is feasible
            qd = np.clip(p0 + s * d + M @ u_lp, lo, hi)
            active = (qd <= lo + BOX_TOL) | (qd >= hi - BOX_TOL)
            return BoxSolution(qd, s, active, -1)
    u, joints, it = found
    qd = np.clip(x + M @ u, lo, hi)
    active = np.zeros(len(x), dtype=bool)
    active[joints] = True
    if s < 1.0:  # at the scaled optimum further joints may sit on a bound with zero multiplier
        active |= (qd <= lo + BOX_TOL) | (qd >= hi - BOX_TOL)
    return BoxSolution(qd, s, active, it)
