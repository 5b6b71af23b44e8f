"""Bounded least-norm rates with the largest task scale, by following the scale from 0 (L8).

``min ‖v‖²`` s.t. ``J v = s ẋ``, ``lo ≤ v ≤ hi``, ``v_j = 0`` off ``mask``, with ``s ≤ 1`` the
largest reachable (docs/MATH.md (L3), (L4)): LNVA under the box, and every reduced robot's
rates after a lock. Its optimum is ``v = clip(Jᵀλ, lo, hi)`` with ``λ`` solving
``J clip(Jᵀλ, lo, hi) = s ẋ``; for a fixed set of joints held at a bound ``λ`` is affine in
``s``, so the solution is piecewise affine in ``s``. From ``s = 0`` (rest, inside the box) the
path is followed from one event (a joint reaches a bound, or a held joint's multiplier
vanishes) to the next until ``s = 1``, or until the free joints' columns lose rank: there a
dual vector ``y`` (``J_Fᵀ y = 0``, ``yᵀẋ = 1``) whose signs agree with the held bounds certifies
that no larger ``s`` is reachable (the LP's optimum), so the rates there are the exact optimum
of (L3). Each event costs ``O(m n + m² |F|)``; a long chain with most joints held needs about
``n − m`` events, where the dual active set of :mod:`.box_qp` restarts from scratch at every
round of the scaling.

Codes: 0 solved; 1 solved at the LP's unique vertex (``s < 1``, the certificate of strict signs
and the vertex solved: every objective has these rates there, and :func:`vertex_state` hands the
vertex to :mod:`.reduced_vertex`); 6 undecided (rest outside the box, a certificate with the wrong signs, a
degenerate event, or no convergence): the caller then solves the problem with
:func:`fault_tolerance.resolution.fast.box_qp.solve_box_rates`, which decides every case.
Compiled by numba (plain Python without it, and tested so); scratch is the caller's.
"""

from __future__ import annotations

from fault_tolerance.numerics.fast.dense import chol_rank_one, chol_solve, cholesky, lu_solve
from fault_tolerance.resolution.box_qp import BOX_TOL
from fault_tolerance.resolution.fast.box_qp import _njit

#: Codes: solved; solved at the LP's unique vertex (s < 1); the path could not decide the
#: problem (the caller's dual active set does).
SOLVED, VERTEX, UNDECIDED = 0, 1, 6
#: ``1 − J_jᵀ G⁻¹ J_j`` below this: holding joint ``j`` leaves the free columns rank-deficient;
#: between it and :data:`RANK_UNSURE` the path does not decide (the free columns would be too
#: ill-conditioned to follow it accurately).
RANK_EPS = 1e-10
RANK_UNSURE = 1e-6
#: The rates' task residual ``‖J q̇ − s ẋ‖∞`` allowed, relative to ``‖ẋ‖∞`` (else undecided).
RESIDUAL_RTOL = 1e-9
#: A certificate's component of the wrong sign beyond this (relative to its largest) fails it.
SIGN_TOL = 1e-9
#: A joint's value past its bound by more than this (times ``1 + |lo| + |hi| + |g₀| + |s g₁|``)
#: is on the wrong side.
STATE_TOL = 1e-11
#: The path is taken when more joints than this leave the box at the unbounded rates: it pays
#: off when most joints end held (a scaled task, a long chain); with a few the dual active set of
#: :mod:`.box_qp`, started from the unbounded rates, needs a step or two (both are exact).
PATH_MIN_OUTSIDE = 3
#: Joint states of the path.
_FREE, _LOWER, _UPPER, _OFF = 0, 1, 2, 3
# Scratch rows of ``ws`` (8, n + 1): g₀, g₁ (``Jᵀλ = g₀ + s g₁``), λ₀, λ₁, w, bound values, λ(s)
# (or a column to update the factor with), ``r₀ = −J_B b``.
_G0, _G1, _L0, _L1, _W, _B, _LS, _R0 = range(8)


@_njit
def pays_off(v, lo, hi, mask) -> bool:  # pragma: no cover - numba
    """Whether more than :data:`PATH_MIN_OUTSIDE` joints on ``mask`` have rates ``v`` off the box."""
    outside = 0
    for j in range(v.shape[0]):
        if mask[j] and not lo[j] - BOX_TOL <= v[j] <= hi[j] + BOX_TOL:
            outside += 1
    return outside > PATH_MIN_OUTSIDE


@_njit
def _factor(J, state, ws, L) -> bool:  # pragma: no cover - numba
    """``J_F J_Fᵀ`` factored into ``L`` from scratch, ``r₀ = −J_B b``; False unless positive definite."""
    m, n = J.shape
    r0 = ws[_R0]
    for i in range(m):
        r0[i] = 0.0
        for k in range(i + 1):
            L[i, k] = 0.0
    for j in range(n):
        if state[j] == _FREE:
            for i in range(m):
                for k in range(i + 1):
                    L[i, k] += J[i, j] * J[k, j]
        elif state[j] != _OFF:
            for i in range(m):
                r0[i] -= J[i, j] * ws[_B, j]
    return cholesky(L, m)


@_njit
def _toggle(J, state, ws, L, j, new, free) -> bool:  # pragma: no cover - numba
    """Joint ``j`` to state ``new``: ``r₀`` and the factor updated (``O(m²)``); False unless PD.

    With few free joints left (``≤ 2m``, where the factor matters most and costs least) it is
    rebuilt from scratch instead of downdated.
    """
    m = J.shape[0]
    held = new != _FREE
    sign = -1.0 if held else 1.0
    for i in range(m):
        ws[_R0, i] += sign * J[i, j] * ws[_B, j]
    state[j] = new
    if held and free <= 2 * m:
        return _factor(J, state, ws, L)
    x = ws[_LS]
    for i in range(m):
        x[i] = J[i, j]
    return chol_rank_one(L, m, x, sign) or _factor(J, state, ws, L)


@_njit
def _slopes(J, xdot, L, ws) -> None:  # pragma: no cover - numba
    """``λ₀ = G⁻¹ r₀``, ``λ₁ = G⁻¹ ẋ`` and ``g₀ = Jᵀλ₀``, ``g₁ = Jᵀλ₁`` for every joint."""
    m, n = J.shape
    lam0, lam1 = ws[_L0], ws[_L1]
    for i in range(m):
        lam0[i], lam1[i] = ws[_R0, i], xdot[i]
    chol_solve(L, m, lam0)
    chol_solve(L, m, lam1)
    g0, g1 = ws[_G0], ws[_G1]
    for j in range(n):
        g0[j], g1[j] = 0.0, 0.0
    for i in range(m):  # along the rows of J: contiguous, vectorised
        a, b = lam0[i], lam1[i]
        for j in range(n):
            g0[j] += J[i, j] * a
            g1[j] += J[i, j] * b


@_njit
def _next_event(state, lo, hi, ws, s):  # pragma: no cover - numba
    """``(t, j)``: the smallest scale ``t ≥ s`` at which joint ``j`` changes state (j = −1: none).

    A joint already on the wrong side at ``s`` (a free one past a bound, a held one whose
    multiplier changed sign, after a degenerate event) changes state at ``t = s``.
    """
    n = lo.shape[0]
    best, arg = 2.0, -1
    for j in range(n):
        g0, g1, st = ws[_G0, j], ws[_G1, j], state[j]
        if st == _OFF:
            continue
        v = g0 + s * g1  # its rounding grows with the terms (steep near the largest scale)
        tol = STATE_TOL * (1.0 + abs(lo[j]) + abs(hi[j]) + abs(g0) + abs(s * g1))
        if st == _FREE:
            if v > hi[j] + tol or v < lo[j] - tol:
                return s, j
            if g1 == 0.0:
                continue
            t = (hi[j] - g0) / g1 if g1 > 0.0 else (lo[j] - g0) / g1
        elif st == _UPPER:
            if v < hi[j] - tol:
                return s, j
            if not g1 < 0.0:
                continue
            t = (hi[j] - g0) / g1
        else:
            if v > lo[j] + tol:
                return s, j
            if not g1 > 0.0:
                continue
            t = (lo[j] - g0) / g1
        t = max(t, s)
        if t < best:
            best, arg = t, j
    return best, arg


@_njit
def _release(J, xdot, state, ws) -> int:  # pragma: no cover - numba
    """Test the dual vector ``y = G⁻¹ J_j`` (in ``ws[_W]``): −1 certified, a held joint to release, or −2.

    With ``g = Jᵀy / yᵀẋ``: ``s = gᵀq̇ ≤ Σ_j max(lo_j g_j, hi_j g_j)`` for every ``q̇`` in the box,
    with equality here when ``g`` vanishes on the free joints and points out of the box at the
    held ones (the LP's dual certificate): then no larger scale is reachable (−1). A held joint
    whose ``g_j`` points into the box can move off its bound and raise ``s``: the most violating
    one is returned (the path goes on with it free). −2: ``y`` is no certificate (``yᵀẋ = 0``, or
    ``g`` does not vanish on the free joints).
    """
    m, n = J.shape
    y = ws[_W]
    c = 0.0
    for i in range(m):
        c += y[i] * xdot[i]
    if not abs(c) > 0.0:
        return -2
    big = 0.0
    for j in range(n):  # g = Jᵀy / (yᵀẋ), kept in the row of g₁ (not needed any more)
        g = 0.0
        for i in range(m):
            g += J[i, j] * y[i]
        ws[_G1, j] = g / c
        if state[j] != _OFF:
            big = max(big, abs(ws[_G1, j]))
    worst, arg = SIGN_TOL * big, -1
    for j in range(n):
        g, st = ws[_G1, j], state[j]
        if st == _FREE and abs(g) > SIGN_TOL * big:
            return -2
        wrong = -g if st == _UPPER else (g if st == _LOWER else 0.0)
        if wrong > worst:
            worst, arg = wrong, j
    return arg


@_njit
def _rates(J, xdot, state, lo, hi, ws, L, s, qd, act) -> int:  # pragma: no cover - numba
    """The rates at scale ``s`` of the current held set into ``qd``, ``act``; the number held.

    ``λ = G⁻¹ (s ẋ − J_B b)`` solved at ``s`` itself: near the largest scale ``g₀ + s g₁`` is a
    difference of large terms.
    """
    m, n = J.shape
    lam = ws[_LS]
    for i in range(m):
        t = s * xdot[i]
        for j in range(n):
            if state[j] == _LOWER or state[j] == _UPPER:
                t -= J[i, j] * ws[_B, j]
        lam[i] = t
    chol_solve(L, m, lam)
    held = 0
    for j in range(n):
        st = state[j]
        if st == _OFF:
            qd[j], act[j] = 0.0, 0.0
        elif st == _FREE:
            v = 0.0
            for i in range(m):
                v += J[i, j] * lam[i]
            qd[j] = min(max(v, lo[j]), hi[j])
            act[j] = 0.0
            if s < 1.0 and (qd[j] <= lo[j] + BOX_TOL or qd[j] >= hi[j] - BOX_TOL):
                act[j] = 1.0
        else:
            qd[j], act[j] = ws[_B, j], 1.0
            held += 1
    return held


@_njit
def _vertex(J, xdot, state, lo, hi, ws, M, s, qd):  # pragma: no cover - numba
    """``(scale, solved)``: the largest scale and free rates solved at the LP's vertex itself.

    With ``m − 1`` free joints left, ``J_F v_F − s ẋ = −J_B b`` is square in ``(v_F, s)``: one
    solve gives both to rounding, where the path's values carry the rounding of its steep last
    steps. Kept only when the solve succeeds inside the box (else ``s`` and ``qd`` are left, and
    ``solved`` is False).
    """
    m, n = J.shape
    z = ws[_LS]
    c = 0
    for i in range(m):
        z[i] = 0.0
    for j in range(n):
        st = state[j]
        if st == _FREE:
            if c == m - 1:
                return s, False
            for i in range(m):
                M[i, c] = J[i, j]
            c += 1
        elif st != _OFF:
            for i in range(m):
                z[i] -= J[i, j] * ws[_B, j]
    if c != m - 1:
        return s, False
    for i in range(m):
        M[i, m - 1] = -xdot[i]
    if not lu_solve(M, m, z) or not 0.0 <= z[m - 1] <= 1.0:
        return s, False
    c = 0
    for j in range(n):
        if state[j] == _FREE:
            if not lo[j] - BOX_TOL <= z[c] <= hi[j] + BOX_TOL:
                return s, False
            c += 1
    c = 0
    for j in range(n):
        if state[j] == _FREE:
            qd[j] = min(max(z[c], lo[j]), hi[j])
            c += 1
    return z[m - 1], True


@_njit
def _on_task(J, xdot, qd, s) -> bool:  # pragma: no cover - numba
    """Whether ``‖J q̇ − s ẋ‖∞ ≤ RESIDUAL_RTOL ‖ẋ‖∞`` (the path's rates are exact)."""
    m, n = J.shape
    big, worst = 0.0, 0.0
    for i in range(m):
        r = -s * xdot[i]
        for j in range(n):
            r += J[i, j] * qd[j]
        worst = max(worst, abs(r))
        big = max(big, abs(xdot[i]))
    return worst <= RESIDUAL_RTOL * big


@_njit
def least_norm_path(J, xdot, lo, hi, mask, qd, act, ws, wsi, L, out):  # pragma: no cover - numba
    """Bounded least-norm rates at the largest scale ``s ≤ 1`` (module doc); ``out[0] = s``.

    ``act`` (n,) gets 1.0 on joints held at a bound; ``out[1]`` is 1.0 when a bound was met.
    ``ws`` (8, n + 1), ``wsi`` (2, n + 1) int and ``L`` (m, m) are scratch. Returns 0, or
    :data:`UNDECIDED` (``out`` then untouched; ``qd`` and ``act`` may hold partial values).
    """
    m, n = J.shape
    state = wsi[0]
    for j in range(n):
        if not mask[j]:
            state[j] = _OFF
        elif lo[j] > BOX_TOL or hi[j] < -BOX_TOL:
            return UNDECIDED  # rest is outside the box: the path has no start
        else:
            state[j] = _FREE
    free = 0
    for j in range(n):
        free += state[j] == _FREE
    if not _factor(J, state, ws, L):
        return UNDECIDED
    s = 0.0
    for _ in range(4 * n + 8):
        _slopes(J, xdot, L, ws)
        t, j = _next_event(state, lo, hi, ws, s)
        if t >= 1.0:
            held = _rates(J, xdot, state, lo, hi, ws, L, 1.0, qd, act)
            if not _on_task(J, xdot, qd, 1.0):
                return UNDECIDED
            out[0], out[1] = 1.0, 1.0 if held else 0.0
            return 0
        s = t
        if state[j] != _FREE:  # its multiplier vanished: the joint leaves its bound
            free += 1
            if not _toggle(J, state, ws, L, j, _FREE, free):
                return UNDECIDED
            continue
        w = ws[_W]
        for i in range(m):
            w[i] = J[i, j]
        chol_solve(L, m, w)
        rho = 1.0
        for i in range(m):
            rho -= J[i, j] * w[i]
        v = ws[_G0, j] + s * ws[_G1, j]
        upper = v - lo[j] > hi[j] - v or (v - lo[j] == hi[j] - v and ws[_G1, j] > 0.0)
        ws[_B, j] = hi[j] if upper else lo[j]
        if free > m and RANK_EPS < rho < RANK_UNSURE:
            return UNDECIDED
        if free > m and rho > RANK_EPS:
            free -= 1
            if not _toggle(J, state, ws, L, j, _UPPER if upper else _LOWER, free):
                return UNDECIDED
            continue
        # Holding j leaves the free columns rank-deficient: the largest scale, if certified.
        _rates(J, xdot, state, lo, hi, ws, L, s, qd, act)  # at s (joint j exactly at its bound)
        state[j] = _UPPER if upper else _LOWER
        k = _release(J, xdot, state, ws)
        if k < -1:
            return UNDECIDED
        if k >= 0:  # a held joint can still raise s: free it and go on (an LP pivot)
            state[k] = _FREE
            if not _factor(J, state, ws, L):
                return UNDECIDED
            continue
        qd[j], act[j] = ws[_B, j], 1.0
        s, exact = _vertex(J, xdot, state, lo, hi, ws, L, s, qd)
        if not _on_task(J, xdot, qd, s):
            return UNDECIDED
        out[0], out[1] = s, 1.0
        return VERTEX if exact and strictly_signed(ws[_G1], state, n) else SOLVED
    return UNDECIDED


@_njit
def strictly_signed(g, state, n) -> bool:  # pragma: no cover - numba
    """Whether a certificate ``g`` points strictly out of the box at every held joint.

    ``g_j > 1e-9 max|g|`` at an upper bound, ``< −1e-9 max|g|`` at a lower one (max over the joints
    not off): then the vertex is the LP's only optimum.
    """
    big = 0.0
    for j in range(n):
        if state[j] != _OFF:
            big = max(big, abs(g[j]))
    for j in range(n):
        if (state[j] == _UPPER and not g[j] > SIGN_TOL * big) or (
            state[j] == _LOWER and not g[j] < -SIGN_TOL * big
        ):
            return False
    return big > 0.0


@_njit
def vertex_state(ws, wsi, vst, vb) -> None:  # pragma: no cover - numba
    """The states and held values of the vertex a :data:`VERTEX` path ended at, into ``vst``, ``vb``.

    ``vst`` (n) int, ``vb`` (n); called before ``ws``, ``wsi`` are used again.
    """
    for j in range(vst.shape[0]):
        vst[j], vb[j] = wsi[0, j], ws[_B, j]
