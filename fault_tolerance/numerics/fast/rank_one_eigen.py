"""Extreme eigenvalues of ``G − v vᵀ`` from the eigenpairs of ``G``: the k_S of all scenarios at once.

Every scenario's ``W_S = J_S J_Sᵀ = G − J_i J_iᵀ`` (eq. 15) is a rank-one downdate of the same
``G = J Jᵀ``. With ``G = V diag(d) Vᵀ`` (``d`` ascending; :func:`eigenpairs`, once per
sample, gives ``Vt = Vᵀ``, the eigenvectors by rows) and ``u = Vᵀ J_i``, the eigenvalues of
``W_S`` are those of ``diag(d) − u uᵀ``: the roots ``μ`` of the secular equation ``1 = Σ_k u_k² / (d_k − μ)``. They interlace, ``μ_1 ≤ d_1 ≤ μ_2 ≤
… ≤ μ_m ≤ d_m``, so

* ``λ_min(W) = d_1 − τ`` with ``τ ∈ [0, ‖u‖²]`` the root of the convex
  ``F(τ) = τ − Σ_{k>1} u_k² τ / (d_k − d_1 + τ) − u_1²`` (:func:`lowest_root`);
* ``λ_max(W) = max(d_m − τ, d_{m−1})`` with ``τ`` the root of the convex increasing
  ``F(τ) = τ + Σ_{k<m} u_k² τ / (d_m − d_k − τ) − u_m²`` before its first pole
  (:func:`highest_root`, measured from the nearer end of its interval).

Each step solves a model of ``F`` that keeps the pole at the root's end of the interval and the
nearest other pole exactly and matches the other poles' value and slope (as LAPACK's ``dlaed4``
does for the divide-and-conquer eigensolver): a quadratic, quadratically convergent, 3-5 steps
of ``O(m)`` each. A scenario costs ``m²`` for ``u`` and those steps, instead of a tridiagonal
reduction and a QL iteration. The iterations keep a bracket (a step that leaves it
bisects it) and report failure after :data:`MAX_STEPS` (seen only for a numerically singular ``G``); the caller then uses
:mod:`fault_tolerance.numerics.fast.small_eigen` on ``W_S`` itself. The roots are accurate to a few ``ε ‖G‖``
(the signs of ``F`` are exact for a nearby ``d`` and ``u``), as the eigenvalues of ``W_S`` by any
backward-stable method.

Example::

    >>> import numpy as np
    >>> from fault_tolerance.numerics.fast.rank_one_eigen import eigenpairs
    >>> A, Vt, d = np.array([[2.0, 1.0], [1.0, 2.0]]), np.empty((2, 2)), np.empty(2)
    >>> eigenpairs(A, 2, Vt, d, np.empty(4)), np.round(d, 12).tolist()
    (True, [1.0, 3.0])
"""

from __future__ import annotations

import math

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.numerics.fast.small_eigen import EPS, _in_range, njit, tridiagonalize

#: Steps of a secular root before reporting failure.
MAX_STEPS = 100
#: A root is taken when the next (quadratically convergent) step is below this fraction of it,
#: or ``F`` is 0: rounding makes ``F``'s root uncertain by a few ulps, the step never smaller.
TOL = 64.0 * EPS


@_inline_once
def _householder_rows(A, m, Vt) -> None:  # pragma: no cover - numba
    """``Vt = Qᵀ = H_{m−2} … H_1 H_0`` from the reflectors :func:`.tridiagonalize` left in ``A``.

    The basis is kept by rows (``Vt[k]`` the k-th vector), so every update below reads and
    writes contiguous memory.
    """
    for r in range(m):
        for c in range(m):
            Vt[r, c] = 1.0 if r == c else 0.0
    for k in range(m - 2, -1, -1):
        tau = A[k, k + 1]
        if tau == 0.0:
            continue
        for r in range(k + 1, m):  # Vt[r, k+1:] ← Vt[r, k+1:] H_k
            s = 0.0
            for c in range(k + 1, m):
                s += A[c, k] * Vt[r, c]
            s *= tau
            for c in range(k + 1, m):
                Vt[r, c] -= s * A[c, k]


@_inline_once
def _ql_vectors_sweep(d, e, lo, j, Vt, m) -> None:  # pragma: no cover - numba
    """One implicit QL step with Wilkinson's shift on the block ``lo..j``; rows of ``Vt`` rotated.

    EISPACK's ``tql2`` with ``√(f² + g²)`` for ``hypot``: :func:`eigenpairs` admits only
    matrices whose largest entry lies in ``[SMALLEST, LARGEST]`` (as ``dsterf``), where no
    square over- or underflows to a wrong sum. ``|g| < 1/(2ε)`` in the shift, since ``e[lo]``
    is not negligible there.
    """
    g = (d[lo + 1] - d[lo]) / (2.0 * e[lo])
    r = math.sqrt(g * g + 1.0)
    g = d[j] - d[lo] + e[lo] / (g + math.copysign(r, g))
    s, c, p = 1.0, 1.0, 0.0
    for i in range(j - 1, lo - 1, -1):
        f, b = s * e[i], c * e[i]
        r = math.sqrt(f * f + g * g)
        e[i + 1] = r
        if r == 0.0:  # underflow: the block splits here
            d[i + 1] -= p
            e[j] = 0.0
            return
        inv = 1.0 / r
        s, c = f * inv, g * inv
        g = d[i + 1] - p
        r = (d[i] - g) * s + 2.0 * c * b
        p = s * r
        d[i + 1] = g + p
        g = c * r - b
        for k in range(m):
            t = Vt[i + 1, k]
            Vt[i + 1, k] = s * Vt[i, k] + c * t
            Vt[i, k] = c * Vt[i, k] - s * t
    d[lo] -= p
    e[lo] = g
    e[j] = 0.0


@_inline_once
def _ql_vectors(d, e, m, Vt) -> bool:  # pragma: no cover - numba
    """Eigenvalues of ``T`` (``d``, ``e``) into ``d`` and ``Vt ← Zᵀ Vt``; False after 30 m sweeps."""
    e[m - 1] = 0.0
    budget = 30 * m
    for lo in range(m):
        while True:
            j = lo
            while j < m - 1 and abs(e[j]) > EPS * (abs(d[j]) + abs(d[j + 1])):
                j += 1
            if j == lo:
                break
            if budget == 0:
                return False
            budget -= 1
            _ql_vectors_sweep(d, e, lo, j, Vt, m)
    return True


@_inline_once
def _sort_pairs(Vt, m, d) -> None:  # pragma: no cover - numba
    """``d`` ascending, the rows of ``Vt`` in the same order."""
    for j in range(1, m):
        k = j
        while k > 0 and d[k] < d[k - 1]:
            d[k], d[k - 1] = d[k - 1], d[k]
            for c in range(m):
                Vt[k, c], Vt[k - 1, c] = Vt[k - 1, c], Vt[k, c]
            k -= 1


@njit
def eigenpairs(A, m, Vt, d, work) -> bool:  # pragma: no cover - numba
    """``A[:m, :m] = Vtᵀ diag(d) Vt``, ``d`` ascending, the eigenvectors the rows of ``Vt``.

    Householder tridiagonalisation (:func:`.tridiagonalize`; lower triangle read, ``A``
    overwritten), the reflectors accumulated, and the implicit QL iteration with its rotations
    applied to the rows of ``Vt`` (EISPACK's ``tql2``). ``work`` holds ``2 m`` numbers. False
    when a number is not finite or out of range, or after ``30 m`` sweeps.
    """
    e, w = work[0:m], work[m : 2 * m]
    tridiagonalize(A, m, d, e, w)
    if not _in_range(d, e, m):
        return False
    _householder_rows(A, m, Vt)
    if not _ql_vectors(d, e, m, Vt):
        return False
    for j in range(m):
        if not abs(d[j]) < math.inf:
            return False
    _sort_pairs(Vt, m, d)
    return True


@_inline_once
def project(Vt, J, i, m, u2) -> float:  # pragma: no cover - numba
    """``u2 = (Vt J_i)²`` entry by entry; returns ``‖u‖²``."""
    total = 0.0
    for k in range(m):
        s = 0.0
        for r in range(m):
            s += Vt[k, r] * J[r, i]
        u2[k] = s * s
        total += u2[k]
    return total


@njit
def _lowest_quadratic(tau, u0, uq, dq, r0, r1):  # pragma: no cover - numba
    """``F`` of :func:`lowest_root` at ``τ`` and the root of its model, from the sums over the far poles.

    ``r0 = Σ_{k>q} u_k² / (δ_k + τ)`` and ``r1 = Σ_{k>q} u_k² / (δ_k + τ)²``: the poles beyond
    ``q`` (the nearest one, at ``τ = −δ_q``) become ``a + b / (δ_q + τ)``, matching their value
    and slope at ``τ``; the model ``τ (1 − a − b / (δ_q + τ)) = u_1²`` is a quadratic with one
    positive root when ``1 − a > 0`` (always so right of the root); NaN when it has none.
    """
    e = dq + tau
    F = tau * (1.0 - r0 - uq / e) - u0
    P = 1.0 - r0 + r1 * e  # 1 − a
    b = uq + r1 * e * e
    B, C = P * dq - b - u0, u0 * dq  # P τ² + B τ − C = 0
    if not P > 0.0:
        return F, math.nan
    D = math.sqrt(B * B + 4.0 * P * C)
    return F, (D - B) / (2.0 * P) if B <= 0.0 else 2.0 * C / (B + D)


@_inline_once
def _lowest_model(d, u2, m, q, tau):  # pragma: no cover - numba
    """``F`` of :func:`lowest_root` at ``τ`` and the root of its model (:func:`_lowest_quadratic`)."""
    r0, r1 = 0.0, 0.0
    for k in range(q + 1, m):
        r = 1.0 / ((d[k] - d[0]) + tau)
        r0 += u2[k] * r
        r1 += u2[k] * r * r
    return _lowest_quadratic(tau, u2[0], u2[q], d[q] - d[0], r0, r1)


@njit
def _advance(F, new, x, lo, hi, below, floor):  # pragma: no cover - numba
    """One safeguarded step of a root in ``x``: ``(next x, lo, hi, done, root)``.

    ``below`` says the root lies above ``x``. The bracket shrinks to the side of the root; the
    root is taken (``done``) when ``F`` is 0 or the next (quadratically convergent) step is below
    ``TOL x + floor`` (rounding makes ``F``'s root uncertain by a few ulps, the step never
    smaller) or the bracket is that small; a step that leaves the bracket bisects it.
    """
    lo, hi = (x, hi) if below else (lo, x)
    done = F == 0.0 or abs(new - x) <= TOL * x + floor or hi - lo <= TOL * hi + floor
    root = x if F == 0.0 else min(max(new, lo), hi)
    return (new if lo <= new <= hi else 0.5 * (lo + hi)), lo, hi, done, root


@njit
def _lowest_start(d, total):  # pragma: no cover - numba
    """The first ``τ`` of :func:`lowest_root`: ``d_1`` (``λ_min = 0``, as ``W ⪰ 0``) or ``‖u‖²``."""
    return min(total, max(d[0], 0.0)) if d[0] > 0.0 else total


@njit
def lowest_root(d, u2, m, total):  # pragma: no cover - numba
    """``(λ_min(diag(d) − u uᵀ), ok)``, ``d`` ascending, ``u2 = u²``, ``total = ‖u‖²``.

    The modelled root of :func:`_lowest_model` from :func:`_lowest_start` (where ``F ≥ 0``),
    inside the bracket ``[0, ‖u‖²]`` (:func:`_advance`); ``d_1 − u_1²`` when ``u`` has no other
    component.
    """
    q = 1
    while q < m and u2[q] == 0.0:
        q += 1
    if q == m:
        return d[0] - u2[0], True
    lo, hi, tau = 0.0, total, _lowest_start(d, total)
    floor = EPS * abs(d[m - 1])  # F is uncertain by rounding: its root by a few ε ‖G‖
    for _ in range(MAX_STEPS):
        F, new = _lowest_model(d, u2, m, q, tau)
        if F != F:  # NaN in d or u: no bracket to keep
            break
        tau, lo, hi, done, root = _advance(F, new, tau, lo, hi, F <= 0.0, floor)
        if done:
            return d[0] - root, True
    return math.nan, False


@_inline_once
def _first_pole(d, u2, m) -> int:  # pragma: no cover - numba
    """Largest ``p < m − 1`` with ``u_p ≠ 0`` (the nearest pole below ``d_m``), -1 if none."""
    for p in range(m - 2, -1, -1):
        if u2[p] > 0.0:
            return p
    return -1


@njit
def _highest_quadratic(x, at_pole, um, up, dp, r0, r1):  # pragma: no cover - numba
    """``F`` of :func:`highest_root` at ``x`` and the root of its model, in the same variable.

    ``x = τ`` (the distance from ``d_m``), or ``x = σ = Δ_p − τ`` (from the pole ``d_p``) when
    ``at_pole``; ``r0``, ``r1`` the sums of ``u_k² / dist_k`` and ``u_k² / dist_k²`` over the
    poles below ``p`` (``dist_k`` measured from the nearer end, without cancellation). Those
    poles become ``a + b / σ``, matching their value and slope at ``x``; the model ``τ (1 + a +
    b / σ) = u_m²`` is a quadratic with one root in the interval.
    """
    tau, sig = (dp - x, x) if at_pole else (x, dp - x)
    F = tau * (1.0 + r0 + up / sig) - um
    A = 1.0 + r0 - r1 * sig  # 1 + a
    b = up + r1 * sig * sig
    if not at_pole:  # A τ² − B τ + C = 0, the smaller root
        B, C = A * dp + b + um, um * dp
        return F, 2.0 * C / (B + math.sqrt(max(B * B - 4.0 * A * C, 0.0)))
    B = A * dp - b - um  # A σ² − B σ − b Δ_p = 0, the positive root
    D = math.sqrt(B * B + 4.0 * A * b * dp)
    return F, (B + D) / (2.0 * A) if B >= 0.0 else 2.0 * b * dp / (D - B)


@njit
def _highest_sums(d, u2, m, p, x, at_pole):  # pragma: no cover - numba
    """``(r0, r1)`` of :func:`_highest_quadratic` at ``x``: the poles below ``p``."""
    top = d[m - 1]
    r0, r1 = 0.0, 0.0
    for k in range(p):
        r = 1.0 / ((d[p] - d[k]) + x) if at_pole else 1.0 / ((top - d[k]) - x)
        r0 += u2[k] * r
        r1 += u2[k] * r * r
    return r0, r1


@_inline_once
def _highest_model(d, u2, m, p, x, at_pole):  # pragma: no cover - numba
    """``F`` of :func:`highest_root` at ``x`` and the root of its model (:func:`_highest_quadratic`)."""
    r0, r1 = _highest_sums(d, u2, m, p, x, at_pole)
    return _highest_quadratic(x, at_pole, u2[m - 1], u2[p], d[m - 1] - d[p], r0, r1)


@njit
def _highest_first(d, u2, m, p, r0, r1, floor):  # pragma: no cover - numba
    """The first step of :func:`highest_root`, from the middle of ``(d_p, d_m)``.

    ``r0``, ``r1`` the sums at the middle (the same from either end). ``F ≤ 0`` there puts the
    root nearer the pole (``x = σ``, bracket ``[0, Δ_p/2]``), otherwise nearer ``d_m`` (``x = τ``,
    bracket ``[0, min(Δ_p/2, u_m²)]``); either way the middle's model gives the first step.
    Returns ``(at_pole, F, x, lo, hi, done, root)`` after that step (:func:`_advance`).
    """
    dp, um, up = d[m - 1] - d[p], u2[m - 1], u2[p]
    half = 0.5 * dp
    F, new = _highest_quadratic(half, True, um, up, dp, r0, r1)
    at_pole = F <= 0.0
    if not at_pole:
        F, new = _highest_quadratic(half, False, um, up, dp, r0, r1)
    x, lo, hi, done, root = _advance(F, new, half, 0.0, half, (F >= 0.0) == at_pole, floor)
    return at_pole, F, x, lo, hi if at_pole else min(hi, um), done, root


@njit
def _highest_value(d, m, p, x, at_pole) -> float:  # pragma: no cover - numba
    """``λ_max`` from the root ``x`` of :func:`highest_root` (at least ``d_{m−1}``, interlacing)."""
    return max(d[p] + x if at_pole else d[m - 1] - x, d[m - 2])


@njit
def highest_root(d, u2, m):  # pragma: no cover - numba
    """``(λ_max(diag(d) − u uᵀ), ok)``, ``d`` ascending, ``u2 = u²``; ``m ≥ 2``.

    No pole below ``d_m`` (``u`` only along its eigenvector): ``d_m − u_m²``; otherwise the
    modelled root of :func:`_highest_model` inside a bracket, measured from the nearer end of
    ``(d_p, d_m)`` (the sign of ``F`` at the middle tells which, and its model gives the first
    step from the pole).
    """
    top, below = d[m - 1], d[m - 2]
    if u2[m - 1] == 0.0 or top == below:
        return top, True
    p = _first_pole(d, u2, m)
    if p < 0:
        return max(top - u2[m - 1], below), True
    floor = EPS * abs(top)
    r0, r1 = _highest_sums(d, u2, m, p, 0.5 * (top - d[p]), True)
    at_pole, F, x, lo, hi, done, root = _highest_first(d, u2, m, p, r0, r1, floor)
    for _ in range(MAX_STEPS):
        if F != F:
            break
        if done:
            return _highest_value(d, m, p, root, at_pole), True
        F, new = _highest_model(d, u2, m, p, x, at_pole)
        x, lo, hi, done, root = _advance(F, new, x, lo, hi, (F >= 0.0) == at_pole, floor)
    return math.nan, False


#: Per-scenario numbers :func:`all_extremes` keeps in its work array (rows of length ``f``).
LANE_ROWS = 7


@_inline_once
def _lowest_lanes(d, U2, m, f, X, ok) -> None:  # pragma: no cover - numba
    """:func:`lowest_root` of every column of ``U2`` (m, f) at once; the roots into ``X[5]``.

    One pass takes a step of every root: the loops run over the scenarios, so the steps of
    different roots are independent (vectorised, overlapped). The nearest pole is ``q = 1``;
    a lane with ``u_2 = 0`` or that does not converge gets ``ok = 0`` (:func:`all_extremes`
    solves it alone). ``X`` rows: ``τ``, lo, hi, ``r0``, ``r1``, root, done.
    """
    tau, lo, hi, r0, r1, root, done = X[0], X[1], X[2], X[3], X[4], X[5], X[6]
    floor, dq = EPS * abs(d[m - 1]), d[1] - d[0]
    for s in range(f):
        total = 0.0
        for k in range(m):
            total += U2[k, s]
        tau[s], lo[s], hi[s] = _lowest_start(d, total), 0.0, total
        ok[s] = 1.0 if U2[1, s] > 0.0 else 0.0
        done[s] = 1.0 - ok[s]
    for _ in range(MAX_STEPS):
        for s in range(f):
            r0[s], r1[s] = 0.0, 0.0
        for k in range(2, m):
            dk = d[k] - d[0]
            for s in range(f):
                r = 1.0 / (dk + tau[s])
                r0[s] += U2[k, s] * r
                r1[s] += U2[k, s] * r * r
        running = 0.0
        for s in range(f):
            F, new = _lowest_quadratic(tau[s], U2[0, s], U2[1, s], dq, r0[s], r1[s])
            x, a, b, fin, r = _advance(F, new, tau[s], lo[s], hi[s], F <= 0.0, floor)
            keep = done[s] != 0.0
            root[s] = root[s] if keep else r
            tau[s], lo[s], hi[s] = (tau[s], lo[s], hi[s]) if keep else (x, a, b)
            done[s] = 1.0 if keep or fin or F != F else 0.0
            ok[s] = ok[s] if F == F else 0.0
            running += 1.0 - done[s]
        if running == 0.0:
            return
    for s in range(f):
        ok[s] = ok[s] * done[s]


@_inline_once
def _highest_lanes(d, U2, m, f, X, ok) -> None:  # pragma: no cover - numba
    """:func:`highest_root` of every column of ``U2`` at once (as :func:`_lowest_lanes`).

    The nearest pole below ``d_m`` is ``p = m − 1``; a lane with ``u_p = 0`` or ``u_m = 0``, or
    ``d_p = d_m``, gets ``ok = 0``. ``X`` rows: ``x``, lo, hi, ``r0``, ``r1``, root (NaN while
    running), measured from the pole.
    """
    x, lo, hi, r0, r1, root, pole = X[0], X[1], X[2], X[3], X[4], X[5], X[6]
    p, top = m - 2, d[m - 1]
    dp, floor = top - d[p], EPS * abs(top)
    half = 0.5 * dp
    for s in range(f):
        ok[s] = 1.0 if U2[p, s] > 0.0 and U2[m - 1, s] > 0.0 and dp > 0.0 else 0.0
        x[s], pole[s], lo[s], hi[s] = half, 1.0, 0.0, half
        root[s] = math.nan if ok[s] != 0.0 else 0.0
    for step in range(MAX_STEPS):
        for s in range(f):
            r0[s], r1[s] = 0.0, 0.0
        for k in range(p):
            near, far = d[p] - d[k], top - d[k]
            for s in range(f):
                r = 1.0 / (near + x[s]) if pole[s] != 0.0 else 1.0 / (far - x[s])
                r0[s] += U2[k, s] * r
                r1[s] += U2[k, s] * r * r
        running = 0.0
        for s in range(f):
            if root[s] == root[s]:  # solved or left
                continue
            if step == 0:  # from the middle (the sums above were taken there, from the pole)
                at_pole, F, nx, a, b, fin, r = _highest_first(
                    d, U2[:, s], m, p, r0[s], r1[s], floor
                )
                pole[s] = 1.0 if at_pole else 0.0
            else:
                at_pole = pole[s] != 0.0
                um, up = U2[m - 1, s], U2[p, s]
                F, new = _highest_quadratic(x[s], at_pole, um, up, dp, r0[s], r1[s])
                nx, a, b, fin, r = _advance(
                    F, new, x[s], lo[s], hi[s], (F >= 0.0) == at_pole, floor
                )
            if F != F:
                ok[s], root[s] = 0.0, 0.0
                continue
            x[s], lo[s], hi[s] = nx, a, b
            if fin:
                root[s] = _highest_value(d, m, p, r, at_pole)
            else:
                running += 1.0
        if running == 0.0:
            return
    for s in range(f):
        ok[s] = ok[s] if root[s] == root[s] else 0.0


@njit
def all_extremes(d, Z, cols, m, U2, X, lam) -> None:  # pragma: no cover - numba
    """``lam[:, s] = (λ_min, λ_max, ok)`` of ``diag(d) − z zᵀ``, ``z = Z[:, cols[s]]``, all s.

    The roots of :func:`lowest_root` and :func:`highest_root`, every scenario's steps side by
    side (:func:`_lowest_lanes`, :func:`_highest_lanes`); a scenario they leave (a zero weight
    at the nearest pole, no convergence) is solved alone by the scalar functions. ``U2`` (m, f)
    receives ``z²``; ``X`` (:data:`LANE_ROWS` + 1, ``max(f, m)``) is scratch; ``lam`` (3, f);
    ``m ≥ 2``.
    """
    f = cols.shape[0]
    for k in range(m):
        for s in range(f):
            z = Z[k, cols[s]]
            U2[k, s] = z * z
    lanes, ok = X[0:LANE_ROWS], X[LANE_ROWS]
    _lowest_lanes(d, U2, m, f, lanes, ok)
    for s in range(f):
        lam[0, s], lam[2, s] = d[0] - lanes[5, s], ok[s]
    _highest_lanes(d, U2, m, f, lanes, ok)
    for s in range(f):
        lam[1, s] = lanes[5, s]
        if lam[2, s] != 0.0 and ok[s] != 0.0:
            continue
        u2, total = lanes[0, :m], 0.0  # the scenario alone, u² in a free row
        for k in range(m):
            u2[k] = U2[k, s]
            total += u2[k]
        lo, good = lowest_root(d, u2, m, total)
        hi, better = highest_root(d, u2, m)
        lam[0, s], lam[1, s], lam[2, s] = lo, hi, 1.0 if good and better else 0.0


@_inline_once
def downdate_extremes(Vt, d, J, i, m, u2):  # pragma: no cover - numba
    """``(λ_min, λ_max, ok)`` of ``G − J_i J_iᵀ`` from ``G = Vtᵀ diag(d) Vt`` (``u2``: m scratch)."""
    total = project(Vt, J, i, m, u2)
    lo, ok = lowest_root(d, u2, m, total)
    if not ok:
        return math.nan, math.nan, False
    if m == 1:
        return lo, lo, True
    hi, ok = highest_root(d, u2, m)
    return lo, hi, ok
