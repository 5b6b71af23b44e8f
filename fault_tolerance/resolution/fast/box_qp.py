"""The bounded problem (L2)-(L4) compiled: the dual active set of :mod:`.boxqp`, in scalar loops.

:func:`nearest_rates` is :func:`fault_tolerance.resolution.box_qp.nearest_point` for the rows ``±Z_j`` of an
orthonormal null-space basis ``Z`` (n, r) (the metric identity of LNVA, MDA and JVJA's least-norm
response): the same rows in the same order, the same tolerances and steps, the same Farkas
certificates, which :func:`solve_box_rates` turns into the task scaling (L3) as
:func:`fault_tolerance.resolution.box_qp.solve_box` does. Besides ``u`` (r) it keeps the rates' motion
``Z u`` (n), so a violation costs one subtraction. Scratch is preallocated by the caller; compiled
by numba (plain Python without it, and tested so). Row norms are those of ``Z``, accurate to
~1e-16 even for a joint that cannot move (which ``1 − ‖Y_j‖²`` of a Cholesky factor is not), so
the same rows are "flat" as in the reference. See docs/MATH.md "Joint limits, compiled" (L7).

Return codes: 0 solved, 1 a Farkas certificate (:func:`nearest_rates`), 4 no rates in the box
reach any ``s ≥ 0`` (:class:`~fault_tolerance.errors.InfeasibleBounds` in the reference), 5 the
active set or the task scaling did not converge: the caller hands the step to the reference,
whose scaling then bisects (docs/MATH.md (L3b)) and so converges.
"""

from __future__ import annotations

import math

from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.fast_cache import njit as _njit
from fault_tolerance.numerics.fast.dense import chol_solve, cholesky
from fault_tolerance.resolution.box_qp import BOX_TOL, MAX_SCALE_ROUNDS, ROW_EPS

# Scratch rows of ``ws`` (8, n + 1): u, z, μ, rr, certificate coefficients, row norms, x, Z u.
_U, _ZV, _MU, _RR, _CC, _NORM, _X, _DELTA = range(8)


@_njit
def _slack(k, n, ws, lo, hi):  # pragma: no cover - numba
    """Slack of row ``k`` (``k < n``: upper bound of joint k, else lower bound of joint k − n)."""
    if k < n:
        return hi[k] - (ws[_X, k] + ws[_DELTA, k])
    j = k - n
    return (ws[_X, j] + ws[_DELTA, j]) - lo[j]


_cholesky = cholesky  # in place (compiled_linalg)
_chol_solve = chol_solve


@_njit
def _dot_rows(Z, r, i, j) -> float:  # pragma: no cover - numba
    t = 0.0
    for c in range(r):
        t += Z[i, c] * Z[j, c]
    return t


@_njit
def _subtract_span(Z, r, rows, nA, ws, coefs, n) -> None:  # pragma: no cover - numba
    """``z ← z − N_A coefs`` (``z = ws[1]``; row ``k`` of ``N_A`` is ``ρ Z_j`` as below)."""
    for a in range(nA):
        ka = rows[a]
        coef = coefs[a] * (-1.0 if ka < n else 1.0)
        ja = ka if ka < n else ka - n
        for c in range(r):
            ws[_ZV, c] -= coef * Z[ja, c]


@_inline_once
def _step_dir(Z, r, rows, nA, p, ws, gram, n) -> float:  # pragma: no cover - numba
    """``rr = (N_AᵀN_A)⁻¹N_Aᵀn_p``, ``z = n_p − N_A rr`` into ``ws``; returns ``‖z‖²``.

    Row ``k`` is ``ρ Z_j`` (``k < n``: upper bound of joint ``j = k``, ``ρ = −1``; else the lower
    bound of ``j = k − n``, ``ρ = 1``). −1 when the active rows' Gram matrix is not positive
    definite (rounding). With ``nA = r`` active rows ``z = 0`` exactly (rounding of the Gram
    solve would otherwise leave a tiny ``z`` and a huge, meaningless step).
    """
    jp = p if p < n else p - n
    rp = -1.0 if p < n else 1.0
    rr = ws[_RR]
    for a in range(nA):
        ka = rows[a]
        ja = ka if ka < n else ka - n
        ra = -1.0 if ka < n else 1.0
        rr[a] = ra * rp * _dot_rows(Z, r, ja, jp)
        for b in range(a + 1):
            kb = rows[b]
            gram[a, b] = (
                ra * (-1.0 if kb < n else 1.0) * _dot_rows(Z, r, ja, kb if kb < n else kb - n)
            )
    if nA and not _cholesky(gram, nA):
        return -1.0
    _chol_solve(gram, nA, rr)
    if nA >= r:  # r independent active rows span R^r: n_p is in their span, z = 0 exactly
        for c in range(r):
            ws[_ZV, c] = 0.0
        return 0.0
    for c in range(r):
        ws[_ZV, c] = rp * Z[jp, c]
    _subtract_span(Z, r, rows, nA, ws, rr, n)
    if nA:  # once more on the residual: the Gram solve's error is refined away (twice is enough)
        cc = ws[_CC]
        for a in range(nA):
            ka = rows[a]
            ja = ka if ka < n else ka - n
            t = 0.0
            for c in range(r):
                t += Z[ja, c] * ws[_ZV, c]
            cc[a] = (-1.0 if ka < n else 1.0) * t
        _chol_solve(gram, nA, cc)
        _subtract_span(Z, r, rows, nA, ws, cc, n)
        for a in range(nA):
            rr[a] += cc[a]
    zz = 0.0
    for c in range(r):
        zz += ws[_ZV, c] * ws[_ZV, c]
    return zz


@_njit
def _most_violated(ws, lo, hi, mask, n) -> int:  # pragma: no cover - numba
    """First row with the smallest normalised slack, if below ``−BOX_TOL``; else −1."""
    best, p = 0.0, -1
    for k in range(2 * n):
        j = k if k < n else k - n
        b = hi[j] if k < n else lo[j]
        if not mask[j] or not math.isfinite(b) or ws[_NORM, j] < ROW_EPS:
            continue
        v = _slack(k, n, ws, lo, hi) / ws[_NORM, j]
        if v < best:
            best, p = v, k
    return p if best < -BOX_TOL else -1


@_inline_once
def _flat_row(ws, lo, hi, mask, n) -> int:  # pragma: no cover - numba
    """First violated row that no null-space motion moves (then the set is empty), or −1."""
    for k in range(2 * n):
        j = k if k < n else k - n
        b = hi[j] if k < n else lo[j]
        if not mask[j] or not math.isfinite(b):
            continue
        e = ws[_X, j] - hi[j] if k < n else lo[j] - ws[_X, j]
        if ws[_NORM, j] < ROW_EPS and e > BOX_TOL:
            return k
    return -1


# Eqn. (L7): Goldfarb & Idnani (1983) on the rows ±Z_j, boxqp.nearest_point in scalar loops.
@_inline_once
def nearest_rates(Z, r, lo, hi, mask, ws, rows, info, gram):  # pragma: no cover - numba
    """Rates ``x + Z u`` in the box on ``mask`` (``x = ws[6]``), ``‖u‖`` least; ``ws[7] = Z u``.

    ``ws`` (8, n + 1): rows u, z, μ, rr, certificate coefficients, row norms, x, Z u. Returns 0
    (``rows[:info[0]]`` the active rows), 1 (a Farkas certificate: rows ``rows[:info[0]]``,
    coefficients ``ws[4]``) or 5 (no convergence).
    """
    n = lo.shape[0]
    nrows = 0
    for j in range(n):
        ws[_DELTA, j] = 0.0
        ws[_NORM, j] = math.sqrt(_dot_rows(Z, r, j, j))
        if mask[j]:
            nrows += math.isfinite(hi[j]) + math.isfinite(lo[j])
    for c in range(r):
        ws[_U, c] = 0.0
    flat = _flat_row(ws, lo, hi, mask, n)
    if flat >= 0:
        rows[0], ws[_CC, 0], info[0] = flat, 1.0, 1
        return 1
    limit, it, nA = 10 * (nrows + 1), 0, 0
    while True:
        p = _most_violated(ws, lo, hi, mask, n)
        if p < 0:
            info[0] = nA
            return 0
        jp = p if p < n else p - n
        mu_p = 0.0
        while True:
            it += 1
            if it > limit:
                return 5
            zz = _step_dir(Z, r, rows, nA, p, ws, gram, n)
            if zz == -1.0:
                return 5
            t1, kk = math.inf, -1
            for a in range(nA):
                if ws[_RR, a] > 1e-14 and ws[_MU, a] / ws[_RR, a] < t1:
                    t1, kk = ws[_MU, a] / ws[_RR, a], a
            sp = _slack(p, n, ws, lo, hi)
            t2 = -sp / zz if zz > 1e-14 * ws[_NORM, jp] * ws[_NORM, jp] else math.inf
            t = min(t1, t2)
            if not math.isfinite(t):  # n_p = N_A rr with rr <= 0: the set is empty
                for a in range(nA, 0, -1):
                    rows[a] = rows[a - 1]
                    ws[_CC, a] = -ws[_RR, a - 1]
                rows[0], ws[_CC, 0], info[0] = p, 1.0, nA + 1
                return 1
            if math.isfinite(t2):
                for c in range(r):
                    ws[_U, c] += t * ws[_ZV, c]
                for i in range(n):
                    d = 0.0
                    for c in range(r):
                        d += Z[i, c] * ws[_ZV, c]
                    ws[_DELTA, i] += t * d
            for a in range(nA):
                ws[_MU, a] -= t * ws[_RR, a]
            mu_p += t
            if t2 <= t1:  # full step: row p joins the active set
                rows[nA], ws[_MU, nA] = p, mu_p
                nA += 1
                break
            for a in range(kk, nA - 1):  # partial step: row kk leaves
                rows[a], ws[_MU, a] = rows[a + 1], ws[_MU, a + 1]
            nA -= 1


@_njit
def _inside(ws, lo, hi, mask) -> bool:  # pragma: no cover - numba
    for j in range(lo.shape[0]):
        if mask[j] and (ws[_X, j] < lo[j] - BOX_TOL or ws[_X, j] > hi[j] + BOX_TOL):
            return False
    return True


@_inline_once
def _certificate_root(p0, d, lo, hi, rows, ws, k, n):  # pragma: no cover - numba
    """``(g0, g1)`` of a certificate: its right-hand side is ``g0 + s g1`` (must be ≤ 0)."""
    g0 = g1 = 0.0
    for t in range(k):
        r = rows[t]
        if r < n:
            g0 += ws[_CC, t] * (p0[r] - hi[r])
            g1 += ws[_CC, t] * d[r]
        else:
            g0 += ws[_CC, t] * (lo[r - n] - p0[r - n])
            g1 -= ws[_CC, t] * d[r - n]
    return g0, g1


@_inline_once
def _violated_row(ws, lo, hi, mask, n) -> int:  # pragma: no cover - numba
    """The only row with a normalised slack below ``−BOX_TOL``; −1 if none, two or a flat one.

    With one such row it is the row :func:`_most_violated` picks, and :func:`_flat_row` finds
    none (a flat violated row, ``ws[_NORM] < ROW_EPS``, gives −1 too). ``ws[_NORM]`` set.
    """
    p = -1
    for k in range(2 * n):
        j = k if k < n else k - n
        b = hi[j] if k < n else lo[j]
        if not mask[j] or not math.isfinite(b):
            continue
        if ws[_NORM, j] < ROW_EPS:
            e = ws[_X, j] - hi[j] if k < n else lo[j] - ws[_X, j]
            if e > BOX_TOL:
                return -1
            continue
        if _slack(k, n, ws, lo, hi) / ws[_NORM, j] < -BOX_TOL:
            if p >= 0:
                return -1
            p = k
    return p


# Eqn. (L7) with one active row: the first step of nearest_rates, when it is also the last.
@_inline_once
def _one_row_rates(Z, r, lo, hi, mask, ws) -> int:  # pragma: no cover - numba
    """:func:`nearest_rates` when one row is violated and its step leaves none: that row, else −1.

    The same operations as the first iteration of :func:`nearest_rates` (``ws[7] = Z u`` as
    there), without its general machinery; −1 (nothing decided) in every other case, which
    :func:`nearest_rates` then solves from the start.
    """
    n = lo.shape[0]
    for j in range(n):
        ws[_DELTA, j] = 0.0
        ws[_NORM, j] = math.sqrt(_dot_rows(Z, r, j, j))
    p = _violated_row(ws, lo, hi, mask, n)
    if p < 0 or r < 1:
        return -1
    jp = p if p < n else p - n
    rp = -1.0 if p < n else 1.0
    zz = 0.0
    for c in range(r):
        ws[_ZV, c] = rp * Z[jp, c]
    for c in range(r):
        zz += ws[_ZV, c] * ws[_ZV, c]
    if not zz > 1e-14 * ws[_NORM, jp] * ws[_NORM, jp]:
        return -1
    t = -_slack(p, n, ws, lo, hi) / zz
    for i in range(n):
        d = 0.0
        for c in range(r):
            d += Z[i, c] * ws[_ZV, c]
        ws[_DELTA, i] += t * d
    return p if _most_violated(ws, lo, hi, mask, n) < 0 else -1


# (L2) with (L3): boxqp.solve_box in scalar loops.
@_njit
def solve_box_rates(
    p0, d, Z, r, lo, hi, mask, qd, act, ws, wsi, gram, out, s0
):  # pragma: no cover - numba
    """Rates ``p₀ + s d + Z u`` in the box on ``mask``, ``s ≤ s₀`` largest; ``out[0] = s``.

    ``s₀ = 1`` unless the largest scale is known: it does not depend on the objective, so the
    rounds of the task scaling (L3) may start there.

    ``act`` (n,) gets 1.0 on joints held at a bound; ``out[1]`` is 1 when a bound was met. Joints
    off ``mask`` get ``p₀ + s d + Z u`` unclipped. Returns 0, 4 (no ``s ≥ 0`` reachable) or 5.
    ``ws`` (8, n + 1), ``wsi`` (2, n + 1) int and ``gram`` (n + 1, n + 1) are scratch.
    """
    n = p0.shape[0]
    rows, info = wsi[0], wsi[1]
    s = s0
    for _ in range(MAX_SCALE_ROUNDS):
        for j in range(n):
            ws[_X, j] = p0[j] + s * d[j]
        if s == 1.0 and _inside(ws, lo, hi, mask):
            for j in range(n):
                x = ws[_X, j]
                qd[j] = min(max(x, lo[j]), hi[j]) if mask[j] else x
                act[j] = 0.0
            out[0], out[1] = 1.0, 0.0
            return 0
        p = _one_row_rates(Z, r, lo, hi, mask, ws)  # the common case, decided without the loop
        if p >= 0:
            rows[0], info[0], st = p, 1, 0
        else:
            st = nearest_rates(Z, r, lo, hi, mask, ws, rows, info, gram)
        if st == 0:
            for j in range(n):
                v = ws[_X, j] + ws[_DELTA, j]
                qd[j] = min(max(v, lo[j]), hi[j]) if mask[j] else v
                act[j] = 0.0
                if s < 1.0 and mask[j] and (qd[j] <= lo[j] + BOX_TOL or qd[j] >= hi[j] - BOX_TOL):
                    act[j] = 1.0
            for t in range(info[0]):
                act[rows[t] if rows[t] < n else rows[t] - n] = 1.0
            out[0], out[1] = s, 1.0
            return 0
        if st == 5:
            return 5
        g0, g1 = _certificate_root(p0, d, lo, hi, rows, ws, info[0], n)
        if not g1 > 0 or -g0 / g1 < -1e-12:
            return 4
        s_new = max(-g0 / g1, 0.0)
        s = s_new if s_new < s else s * (1.0 - 1e-12) - 1e-15
    return 5
