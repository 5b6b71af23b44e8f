"""A reduced robot's rates at its largest task scale, from the whole arm's LP vertex (L9).

When the whole arm's least-norm path (:mod:`.least_norm_path`, L8) ends at the LP's unique vertex
(``s < 1``: ``m − 1`` free joints, the others held at a bound, a dual certificate of strict signs),
every reduced robot's largest scale is below it too, and its exact bounded least-norm rates are
its own LP vertex: ``max s`` s.t. ``J v = s ẋ``, ``lo ≤ v ≤ hi``, ``v_S = 0``. That vertex is a few
pivots of the bounded dual simplex away from the whole arm's: locking the joints ``S`` changes the
held values or removes basic columns, never the reduced costs' signs. The whole arm's basis
inverse is formed once (:func:`whole_basis`); each reduced robot starts from a copy and updates it
in product form, ``O(m² + m n)`` a pivot, where the path from ``s = 0`` needs about ``n − m``
events of ``O(m n + m² |F|)``.

The result is accepted only when it is certified the same way as the path's: inside the box, on
the task to ``RESIDUAL_RTOL``, at a nonsingular basis, with a dual certificate of strict signs
(then the vertex is the problem's only optimum, whatever the objective). Otherwise, or after
:data:`MAX_PIVOTS`, the code is :data:`~.least_norm_path.UNDECIDED` and the caller takes the path.
Compiled by numba (plain Python without it, and tested so); scratch is the caller's.
"""

from __future__ import annotations

from fault_tolerance.resolution.box_qp import BOX_TOL
from fault_tolerance.resolution.fast.box_qp import _njit
from fault_tolerance.resolution.fast.least_norm_path import (  # the path's states
    _FREE,
    _LOWER,
    _OFF,
    _UPPER,
    SIGN_TOL,
    UNDECIDED,
    _on_task,
    strictly_signed,
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
def whole_basis(J, xdot, vst, vb, basic0, Binv0, B, r0) -> bool:  # pragma: no cover - numba
    """The whole arm's vertex basis: ``basic0`` (free joints, then ``n`` for ``s``), ``B⁻¹``, ``r₀``.

    ``r₀ = −J_held b``. Once per step, shared by every reduced robot; False unless the vertex has
    ``m − 1`` free joints and a nonsingular basis. ``B`` (m, m) scratch.
    """
    m, n = J.shape
    c = 0
    for j in range(n):
        if vst[j] == _FREE:
            if c == m - 1:
                return False
            basic0[c] = j
            c += 1
    if c != m - 1:
        return False
    basic0[m - 1] = n
    for i in range(m):
        t = 0.0
        for j in range(n):
            if vst[j] == _LOWER or vst[j] == _UPPER:
                t -= J[i, j] * vb[j]
        r0[i] = t
        for c in range(m):
            col = basic0[c]
            B[i, c] = J[i, col] if col < n else -xdot[i]
    return _invert(B, Binv0, m)


@_njit
def _start(
    J, vst, vb, S, k, basic0, Binv0, r0, st, b, basic, Binv, r
) -> None:  # pragma: no cover - numba
    """The whole arm's basis with ``S`` locked: states, held values, basis, ``B⁻¹`` and ``r``."""
    m, n = J.shape
    for j in range(n):
        st[j], b[j] = vst[j], vb[j]
    for i in range(m):
        r[i] = r0[i]
        basic[i] = basic0[i]
        for c in range(m):
            Binv[i, c] = Binv0[i, c]
    for t in range(k):
        j = S[t]
        if st[j] == _FREE:  # basic: it leaves at 0 first
            st[j] = _FIXED
        else:  # held at b_j: now at 0
            if st[j] != _OFF:
                for i in range(m):
                    r[i] += J[i, j] * b[j]
            st[j] = _OFF


@_njit
def _pivot(J, Binv, p, q, u) -> bool:  # pragma: no cover - numba
    """``B⁻¹`` after column ``p`` of ``B`` becomes ``J_q`` (product form, ``O(m²)``); ``u`` scratch."""
    m = J.shape[0]
    for i in range(m):
        t = 0.0
        for c in range(m):
            t += Binv[i, c] * J[c, q]
        u[i] = t
    if u[p] == 0.0:
        return False
    f = 1.0 / u[p]
    for c in range(m):
        Binv[p, c] *= f
    for i in range(m):
        if i != p and u[i] != 0.0:
            g = u[i]
            for c in range(m):
                Binv[i, c] -= g * Binv[p, c]
    return True


@_njit
def _solve(Binv, r, x) -> None:  # pragma: no cover - numba
    """``x = B⁻¹ r``."""
    m = x.shape[0]
    for i in range(m):
        t = 0.0
        for c in range(m):
            t += Binv[i, c] * r[c]
        x[i] = t


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
def _certificate(J, st, Binv, sp, g) -> None:  # pragma: no cover - numba
    """``g = Jᵀy`` with ``y = −(B⁻¹)_{sp}`` (``J_Fᵀy = 0``, ``yᵀẋ = 1``), zero at the locked joints."""
    m, n = J.shape
    for j in range(n):
        t = 0.0
        if st[j] != _OFF and st[j] != _FIXED:
            for i in range(m):
                t -= Binv[sp, i] * J[i, j]
        g[j] = t


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
def reduced_vertex(J, xdot, lo, hi, S, k, vtx, top, qd, act, out):  # pragma: no cover - numba
    """Exact bounded least-norm rates of the reduced robot ``S[:k]`` (L9); ``out[0] = s``.

    ``vtx = (vst, vb, basic0, Binv0, r0, st, b, basic, Binv, x, r, u)``: the whole arm's vertex
    (:func:`.least_norm_path.vertex_state`: states (n) int and held values (n)) and its basis
    (:func:`whole_basis`: ``basic0`` (m) int, ``B⁻¹`` (m, m), ``r₀`` (m)), at its scale
    ``top < 1``; then scratch: ``st`` (n) int, ``b`` (n), ``basic`` (m) int, ``Binv`` (m, m),
    ``x``, ``r``, ``u`` (m). Returns 0, or :data:`~.least_norm_path.UNDECIDED` (``qd``, ``act``
    may then hold partial values).
    """
    m, n = J.shape
    vst, vb, basic0, Binv0, r0, st, b, basic, Binv, x, r, u = vtx
    _start(J, vst, vb, S, k, basic0, Binv0, r0, st, b, basic, Binv, r)
    sp = m - 1
    for _ in range(MAX_PIVOTS):
        _solve(Binv, r, x)
        p, bound = _leaving(st, basic, lo, hi, x, n)
        if p < 0:
            break
        q = _entering(J, st, Binv, p, sp, x[p] < bound)
        if q < 0 or not _pivot(J, Binv, p, q, u):
            return UNDECIDED
        leave = basic[p]
        if st[leave] == _FIXED:
            st[leave] = _OFF
        else:
            st[leave], b[leave] = (_UPPER if bound == hi[leave] else _LOWER), bound
            for i in range(m):
                r[i] -= J[i, leave] * bound
        for i in range(m):  # q leaves its bound b_q
            r[i] += J[i, q] * b[q]
        st[q], basic[p] = _FREE, q
    else:
        return UNDECIDED
    s = _rates_at(st, b, basic, lo, hi, x, n, qd, act)
    _certificate(J, st, Binv, sp, b)  # the held values are in qd now: b holds g
    if not (-BOX_TOL <= s <= top + BOX_TOL and strictly_signed(b, st, n)):
        return UNDECIDED
    if not _on_task(J, xdot, qd, s):
        return UNDECIDED
    out[0], out[1] = max(s, 0.0), 1.0
    return 0
