"""A reduced robot's rates at its largest task scale, from the whole arm's LP vertex (L9).

When the whole arm's least-norm path (:mod:`.least_norm_path`, L8) ends at the LP's unique vertex
(``s < 1``: ``m − 1`` free joints, the others held at a bound, a dual certificate of strict signs),
every reduced robot's largest scale is below it too, and its exact bounded least-norm rates are
its own LP vertex: ``max s`` s.t. ``J v = s ẋ``, ``lo ≤ v ≤ hi``, ``v_S = 0``. That vertex is a few
pivots of the bounded dual simplex away from the whole arm's: locking the joints ``S`` changes the
held values or removes basic columns, never the reduced costs' signs. Each pivot costs ``O(m³ + m
n)``, where the path from ``s = 0`` needs about ``n − m`` events.

The result is accepted only when it is certified the same way as the path's: inside the box, on
the task to ``RESIDUAL_RTOL``, at a nonsingular basis, with a dual certificate of strict signs
(then the vertex is the problem's only optimum, whatever the objective). Otherwise, or after
:data:`MAX_PIVOTS`, the code is :data:`~.least_norm_path.UNDECIDED` and the caller takes the path.
Compiled by numba (plain Python without it, and tested so); scratch is the caller's.
"""

from __future__ import annotations

from fault_tolerance.resolution.box_qp import BOX_TOL
from fault_tolerance.resolution.fast.box_qp import _njit
from fault_tolerance.resolution.fast.least_norm_path import (
    _FREE,
    _LOWER,
    _OFF,
    _UPPER,
    SIGN_TOL,
    UNDECIDED,
    _on_task,
)

#: Dual simplex pivots tried before the caller's path takes over.
MAX_PIVOTS = 12
#: A locked joint still in the basis (it must leave at 0 first).
_FIXED = 4


@_njit
def _invert(B, Binv, m) -> bool:  # pragma: no cover - numba
    """``Binv = B⁻¹`` by Gauss-Jordan with partial pivoting (``B`` overwritten); False if singular."""
    for i in range(m):
        for j in range(m):
            Binv[i, j] = 1.0 if i == j else 0.0
    for c in range(m):
        p, big = c, abs(B[c, c])
        for i in range(c + 1, m):
            if abs(B[i, c]) > big:
                p, big = i, abs(B[i, c])
        if not big > 0.0:
            return False
        if p != c:
            for j in range(m):
                B[c, j], B[p, j] = B[p, j], B[c, j]
                Binv[c, j], Binv[p, j] = Binv[p, j], Binv[c, j]
        f = 1.0 / B[c, c]
        for j in range(m):
            B[c, j] *= f
            Binv[c, j] *= f
        for i in range(m):
            if i != c and B[i, c] != 0.0:
                g = B[i, c]
                for j in range(m):
                    B[i, j] -= g * B[c, j]
                    Binv[i, j] -= g * Binv[c, j]
    return True


@_njit
def _basic_values(J, xdot, st, b, basic, B, Binv, x) -> bool:  # pragma: no cover - numba
    """``x = B⁻¹ (−J_held b)`` for the basis ``basic`` (joint columns, ``n`` for ``s``); ``Binv`` kept."""
    m, n = J.shape
    for c in range(m):
        col = basic[c]
        for i in range(m):
            B[i, c] = J[i, col] if col < n else -xdot[i]
    if not _invert(B, Binv, m):
        return False
    for i in range(m):  # r = −J_held b into B's first column (B is scratch now)
        t = 0.0
        for j in range(n):
            if st[j] == _LOWER or st[j] == _UPPER:
                t -= J[i, j] * b[j]
        B[i, 0] = t
    for i in range(m):
        t = 0.0
        for k in range(m):
            t += Binv[i, k] * B[k, 0]
        x[i] = t
    return True


@_njit
def _leaving(st, basic, lo, hi, x, n):  # pragma: no cover - numba
    """``(p, bound)``: the basis position to leave and the bound it leaves at; ``p = −1`` if none.

    A locked joint still basic leaves first (at 0); else the largest violation of the box.
    """
    p, bound, worst = -1, 0.0, BOX_TOL
    for c in range(basic.shape[0]):
        col = basic[c]
        if col == n:
            continue
        if st[col] == _FIXED:
            return c, 0.0
        v = x[c]
        if v - hi[col] > worst:
            p, bound, worst = c, hi[col], v - hi[col]
        elif lo[col] - v > worst:
            p, bound, worst = c, lo[col], lo[col] - v
    return p, bound


@_njit
def _entering(J, st, Binv, p, sp, rises) -> int:  # pragma: no cover - numba
    """The held joint entering the basis at row ``p`` by the dual ratio test; −1 if none.

    ``α_j = (B⁻¹)_p J_j``, reduced cost ``d_j = (B⁻¹)_{sp} J_j`` (``sp``: the position of ``s``);
    ``rises``: the leaving value must grow to its bound.
    """
    m, n = J.shape
    best, q = 0.0, -1
    for j in range(n):
        sj = st[j]
        if sj != _LOWER and sj != _UPPER:
            continue
        alpha, d = 0.0, 0.0
        for i in range(m):
            alpha += Binv[p, i] * J[i, j]
            d += Binv[sp, i] * J[i, j]
        if (sj == _LOWER) == rises:
            ok = alpha < -SIGN_TOL
        else:
            ok = alpha > SIGN_TOL
        if not ok:
            continue
        ratio = abs(d) / abs(alpha)
        if q < 0 or ratio < best:
            best, q = ratio, j
    return q


@_njit
def _strict(J, st, Binv, sp) -> bool:  # pragma: no cover - numba
    """Whether ``g = Jᵀy`` (``y = −(B⁻¹)_{sp}``) points strictly out of the box at every held joint."""
    m, n = J.shape
    big = 0.0
    for j in range(n):
        if st[j] != _OFF and st[j] != _FIXED:
            g = 0.0
            for i in range(m):
                g -= Binv[sp, i] * J[i, j]
            big = max(big, abs(g))
    for j in range(n):
        sj = st[j]
        if sj == _LOWER or sj == _UPPER:
            g = 0.0
            for i in range(m):
                g -= Binv[sp, i] * J[i, j]
            if (sj == _UPPER and not g > SIGN_TOL * big) or (
                sj == _LOWER and not g < -SIGN_TOL * big
            ):
                return False
    return big > 0.0


@_njit
def _start(vst, vb, S, k, st, b, basic, n) -> int:  # pragma: no cover - numba
    """The whole arm's vertex with ``S`` locked into ``st``, ``b``, ``basic``; the basis size."""
    for j in range(n):
        st[j], b[j] = vst[j], vb[j]
    for t in range(k):
        j = S[t]
        st[j] = _FIXED if st[j] == _FREE else _OFF
    c = 0
    for j in range(n):
        if st[j] == _FREE or st[j] == _FIXED:
            if c < basic.shape[0]:
                basic[c] = j
            c += 1
    if c < basic.shape[0]:
        basic[c] = n
    return c + 1


@_njit
def _rates_at(st, b, basic, lo, hi, x, n, qd, act) -> float:  # pragma: no cover - numba
    """The vertex's rates into ``qd`` (held at their bound, free clipped), ``act``; its scale."""
    s = 0.0
    for j in range(n):
        sj = st[j]
        held = sj == _LOWER or sj == _UPPER
        qd[j] = b[j] if held else 0.0
        act[j] = 1.0 if held else 0.0
    for c in range(basic.shape[0]):
        col = basic[c]
        if col == n:
            s = x[c]
            continue
        qd[col] = min(max(x[c], lo[col]), hi[col])
        if qd[col] <= lo[col] + BOX_TOL or qd[col] >= hi[col] - BOX_TOL:
            act[col] = 1.0
    return s


# Eqn. (L9): the reduced robot's LP vertex by the dual simplex from the whole arm's.
@_njit
def reduced_vertex(
    J, xdot, lo, hi, S, k, vst, vb, s_top, qd, act, st, b, basic, B, Binv, x, out
):  # pragma: no cover - numba
    """Exact bounded least-norm rates of the reduced robot ``S[:k]`` (L9); ``out[0] = s``.

    ``vst`` (n) int, ``vb`` (n): the whole arm's vertex (:func:`.least_norm_path.least_norm_path`
    states and held values) at its scale ``s_top < 1``. ``st`` (n) int, ``b`` (n), ``basic`` (m)
    int, ``B``, ``Binv`` (m, m) and ``x`` (m) are scratch. Returns 0, or
    :data:`~.least_norm_path.UNDECIDED` (``qd``, ``act`` may then hold partial values).
    """
    m, n = J.shape
    if _start(vst, vb, S, k, st, b, basic, n) != m:
        return UNDECIDED
    sp = m - 1
    for _ in range(MAX_PIVOTS):
        if not _basic_values(J, xdot, st, b, basic, B, Binv, x):
            return UNDECIDED
        p, bound = _leaving(st, basic, lo, hi, x, n)
        if p < 0:
            break
        q = _entering(J, st, Binv, p, sp, x[p] < bound)
        if q < 0:
            return UNDECIDED
        leave = basic[p]
        if st[leave] == _FIXED:
            st[leave] = _OFF
        else:
            st[leave], b[leave] = (_UPPER if bound == hi[leave] else _LOWER), bound
        st[q], basic[p] = _FREE, q
    else:
        return UNDECIDED
    s = _rates_at(st, b, basic, lo, hi, x, n, qd, act)
    if not (-BOX_TOL <= s <= s_top + BOX_TOL and _strict(J, st, Binv, sp)):
        return UNDECIDED
    if not _on_task(J, xdot, qd, s):
        return UNDECIDED
    out[0], out[1] = max(s, 0.0), 1.0
    return 0
