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


#: Task-set deviation [rad/s] below which a metric solution needs no well-conditioned fallback.
POLISH_TOL = 1e-11


#: Rounds of (L3): a certificate's root, then a solve there (a handful suffice in practice).
MAX_SCALE_ROUNDS = 50
#: Certificate rounds before (L3b) bisects between a feasible and an infeasible scaling.
CERT_ROUNDS = 8
#: (L3b) stops when the bracket of the largest scaling is this narrow.
SCALE_BRACKET = 1e-13


def _at_scale(p0, d, M, lo, hi, Nk, e0, e1, joint, s):
    """(L2) at the task scaling ``s``: a :class:`BoxSolution`, or the certificate's root (float)."""
    x = p0 + s * d
    try:
        found = nearest_point(Nk, e0 + s * e1)
    except InfeasibleBounds:  # cycling by rounding on a nearly degenerate polytope: not certified
        return np.nan
    if not isinstance(found, Certificate):
        u, rows, it = found
        qd = np.clip(x + M @ u, lo, hi)
        active = np.zeros(len(p0), dtype=bool)
        active[joint[rows]] = True
        if s < 1.0:  # at the scaled optimum more joints may sit on a bound, multiplier 0
            active |= (qd <= lo + BOX_TOL) | (qd >= hi - BOX_TOL)
        return BoxSolution(qd, s, active, it)
    g0 = float(found.coef @ e0[found.rows])
    g1 = float(found.coef @ e1[found.rows])
    return -g0 / g1 if g1 > 0 else -np.inf  # every feasible s lies below the root


def _rows(p0, d, M, lo, hi) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The constraint rows of the box at scale s: ``e_k(s) = e0_k + s e1_k``."""
    Nk, e_lo_hi, joint, side = _constraints(M, lo, hi)  # rows for x = 0; shifted below
    e0 = e_lo_hi + side * p0[joint]  # e_k(s) = e0_k + s e1_k (upper: x − hi, lower: lo − x)
    e1 = side * d[joint]
    return Nk, e0, e1, joint


# Eqn. (L3): the largest task scaling, from certificates; (L3b) bisection when rounding stalls.
def largest_scale(p0, d, M, lo, hi):
    """``(s, solution at s)``: the largest ``s ∈ [0, 1]`` with ``p₀ + s d + M u`` in the box.

    Certificate roots are upper bounds of ``s``; a solve at a root either succeeds (that root is
    the largest ``s``) or gives a smaller root. When rounding stalls that descent (a root not below
    the tried ``s``, or an uncertified failure), bisection between the largest feasible ``s`` found
    (``s = 0`` first) and the smallest infeasible one closes the bracket to
    :data:`SCALE_BRACKET`; the feasible end is returned. Raises :class:`InfeasibleBounds` only
    when ``s = 0`` itself is infeasible.
    """
    rows = _rows(p0, d, M, lo, hi)
    s, s_bad = 1.0, np.inf
    for _ in range(CERT_ROUNDS):
        got = _at_scale(p0, d, M, lo, hi, *rows, s)
        if isinstance(got, BoxSolution):
            return s, got
        s_bad = min(s_bad, s)
        if not np.isfinite(got) or got >= s or got < 0.0:
            break
        s = got
    good = _at_scale(p0, d, M, lo, hi, *rows, 0.0)
    if not isinstance(good, BoxSolution):
        raise InfeasibleBounds(
            "no joint rates inside the rate box reach any fraction of the task velocity, "
            "not even zero (is the configuration outside its joint limits?)"
        )
    s_good, s_bad = 0.0, min(s_bad, 1.0)
    while s_bad - s_good > SCALE_BRACKET:
        mid = 0.5 * (s_good + s_bad)
        got = _at_scale(p0, d, M, lo, hi, *rows, mid)
        if isinstance(got, BoxSolution):
            s_good, good = mid, got
        else:
            s_bad = mid
            if np.isfinite(got) and s_good < got < mid:  # a certified, tighter upper bound
                at = _at_scale(p0, d, M, lo, hi, *rows, got)
                if isinstance(at, BoxSolution):
                    s_good, good = got, at
                    break
                s_bad = got
    return s_good, good


def _polish(sol: BoxSolution, x, Z, lo, hi) -> BoxSolution:
    """Back onto the affine set ``x + range Z`` by moving the joints off their bounds only.

    An ill-conditioned metric basis ``M`` leaves the rates off the task's set by rounding times
    its condition; the least-norm correction on the free joints removes it (``Yᵀ c = Yᵀ δ``, ``Y``
    the orthogonal complement of ``Z``, ``c`` zero on the joints at a bound).
    """
    n, r = Z.shape
    Y = np.linalg.svd(Z, full_matrices=True)[0][:, r:] if r else np.eye(n)
    rhs = Y.T @ (sol.qd - x)  # the part of the deviation the task sees
    free = ~((sol.qd <= lo + BOX_TOL) | (sol.qd >= hi - BOX_TOL))
    if not free.any() or not np.any(rhs):
        return sol
    c = np.zeros(n)
    c[free] = np.linalg.lstsq(Y[free].T, rhs, rcond=None)[0]
    qd = np.clip(sol.qd - c, lo, hi)
    return BoxSolution(qd, sol.scale, sol.active, sol.iterations)


def _refine(sol: BoxSolution, x, Z, H, lo, hi) -> BoxSolution:
    """The metric's optimum on ``sol``'s active set, solved on well-conditioned constraints.

    ``min q̇ᵀHq̇`` with ``q̇ ∈ x + range Z`` and the active joints on their bounds: ``q̇ = q_p + K y``
    with ``K`` an orthonormal basis of the free joints' motions in ``range Z``, ``KᵀHK y = −KᵀH q_p``.
    The constraints then hold to rounding whatever the conditioning of ``H``; kept only when the
    refined rates stay in the box (the same active set is then optimal, to rounding).
    """
    act = np.flatnonzero(sol.active)
    b = np.where(np.abs(sol.qd - lo) <= np.abs(sol.qd - hi), lo, hi)[act]
    A = Z[act]  # (k, r): the active joints' rows
    w = np.linalg.lstsq(A, b - x[act], rcond=None)[0] if len(act) else np.zeros(Z.shape[1])
    q_p = x + Z @ w
    if len(act):
        _, sv, Vt = np.linalg.svd(A, full_matrices=True)
        rank = int(np.sum(sv > 1e-12 * max(float(sv[0]) if len(sv) else 0.0, 1e-300)))
        K = Z @ Vt[rank:].T
    else:
        K = Z
    if K.shape[1]:
        G = K.T @ H @ K
        q_p = q_p - K @ np.linalg.solve(G, K.T @ (H @ q_p))
    if np.any(q_p < lo - 1e-10) or np.any(q_p > hi + 1e-10) or not np.all(np.isfinite(q_p)):
        return sol
    if _off_task(q_p, x, Z) > POLISH_TOL or q_p @ H @ q_p > sol.qd @ H @ sol.qd:
        return sol
    return BoxSolution(np.clip(q_p, lo, hi), sol.scale, sol.active, sol.iterations)


def _finish(sol, x, Z, H, lo, hi) -> BoxSolution:
    sol = _polish(sol, x, Z, lo, hi)
    return sol if H is None else _refine(sol, x, Z, H, lo, hi)


def _off_task(qd, x, Z) -> float:
    """Largest deviation of ``qd`` from the affine set ``x + range Z``."""
    dev = qd - x
    return float(np.abs(dev - Z @ (Z.T @ dev)).max(initial=0.0))


def solve_box(p0, d, M, lo, hi, Z=None, H=None) -> BoxSolution:
    """(L2) with (L3): rates ``p₀ + s d + M u`` inside ``[lo, hi]``, ``s`` as large as possible.

    ``p₀ + d`` is the unbounded optimum at ``s = 1``, ``M`` (n, r) the metric-scaled null-space
    basis. Returns the unbounded optimum itself when it is inside the box. ``Z`` (n, r): an
    orthonormal basis of the same null space, to find ``s`` on a well-conditioned problem when
    ``M`` is not (the scaling does not depend on the metric); the metric's QP is then solved at
    that ``s`` (slightly below it if rounding calls the touching polytope empty) and, given the
    metric ``H`` (n, n), refined on its active set by :func:`_refine`. Raises
    :class:`InfeasibleBounds` when no ``s ∈ [0, 1]`` is reachable.
    """
    n = len(p0)
    x = p0 + d
    if np.all(x >= lo - BOX_TOL) and np.all(x <= hi + BOX_TOL):
        return BoxSolution(np.clip(x, lo, hi), 1.0, np.zeros(n, dtype=bool), 0)
    if Z is None:
        return largest_scale(p0, d, M, lo, hi)[1]
    got = _at_scale(p0, d, M, lo, hi, *_rows(p0, d, M, lo, hi), 1.0)
    if isinstance(got, BoxSolution):
        return _finish(got, x, Z, H, lo, hi)
    # the same affine sets, from their least-norm points (p₀ + s d may lie far outside the box)
    s, fallback = largest_scale(p0 - Z @ (Z.T @ p0), d - Z @ (Z.T @ d), Z, lo, hi)
    rows = _rows(p0, d, M, lo, hi)
    for shrink in (0.0, 1e-13, 1e-11):
        got = _at_scale(p0, d, M, lo, hi, *rows, s * (1.0 - shrink))
        if isinstance(got, BoxSolution):
            got = _finish(got, p0 + got.scale * d, Z, H, lo, hi)
            if _off_task(got.qd, p0 + got.scale * d, Z) <= POLISH_TOL or s == 1.0:
                return got
            break  # too few free joints to polish: the scaled set is (nearly) a vertex
    # the scaled set is (nearly) one point, the metric's rounding misses it: the well-conditioned
    # solve's point of it (the same point up to that rounding)
    return fallback
