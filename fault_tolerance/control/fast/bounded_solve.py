"""The Controller's bounded step compiled: factors, reduced robots (L4), JVJA's target, one entry.

:func:`bounded_solve` solves the bounded problem of :mod:`fault_tolerance.resolution.bounded` for LNVA, JVJA
(least-norm response, scenarios of any size, weights) and MDA from ``J`` and ``ẋ`` with the
dual active set of :mod:`fault_tolerance.resolution.fast.box_qp`: a Cholesky factor of ``J Jᵀ`` gives
``a = J⁺ẋ``, a Householder QR of ``Jᵀ`` an orthonormal null-space basis ``Z`` (``N = Z Zᵀ``,
never formed), each scenario's (G1) rates come from ``Z`` and, only when they leave the box, the
reduced robot's basis ``Z_S`` (L6: ``Z`` reflected so that the locked joints' rows vanish) and
its bounded rates (L4). :func:`free_then_bounded` is the whole bounded step of LNVA and
single-joint JVJA after the Jacobian in one compiled call: the unbounded step and the box check
(:mod:`fault_tolerance.control.fast.bounded_free`) and, only when a bound is met,
:func:`bounded_solve`, all in the buffers of :func:`workspace` (two arrays, so the call is cheap). Plain Python without
numba (and tested so). See docs/MATH.md "Joint limits, compiled".

Codes of :func:`bounded_solve`: 0 solved, 1 no certificate ``σ_min(J) ≥ SIGMA_EPS`` (the
reference damps), 2 a pivot below the threshold (intolerable, or damped with ``tolerate``), 3 a
reduced Jacobian near its singularity (``σ_min(J_S) < SIGMA_EPS``, where the reference solves the
reduced robot exactly from ``J_S`` with no damping) or too near that threshold to decide, 4 no rates in the box reach any ``s ≥ 0``, 5 the
active set did not converge. Every code but 0 is left to the reference.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.control.fast.bounded_free import _free, free_shape
from fault_tolerance.control.fast.box_check import compiled_box_status
from fault_tolerance.control.fast.step import _inline, compiled_kernel
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.numerics.linalg import RANK_RTOL
from fault_tolerance.resolution.box_qp import BOX_TOL
from fault_tolerance.resolution.fast.box_basis import (
    factor,
    null_basis,
    null_project,
    reduced_basis,
    reduced_rates,
    undamped,
)
from fault_tolerance.resolution.fast.box_qp import _njit, solve_box_rates

_step_kernel = compiled_kernel("step")
_box_status = compiled_box_status()


# -- the whole bounded step after the Jacobian, in one call --------------------------------------

#: Modes of :func:`bounded_solve` (and of the workspace).
LNVA, JVJA, MDA, JVJA_MULTI = 0, 1, 2, 3
#: Float sections of the workspace: name and shape (in n, m, f, s = largest scenario, k = columns).
_FLOAT = (("G", "mm"), ("B", "mn"), ("fw", "2n"), ("lim", "3n"), ("buf", "4n"), ("c", "n"),
          ("p4", "4"), ("prm", "2"), ("state", "n+2"), ("p3", "3"), ("Zm", "nn"), ("V", "7n"),
          ("Lm", "mm"), ("Y", "mn"), ("z", "m"), ("NSS", "ss"), ("ys", "s"), ("wsf", "8(n+1)"),
          ("gram", "(n+1)(n+1)"), ("wrel", "f"), ("mws", "multi"), ("QA", "nm"), ("hb", "m"),
          ("Zs", "nn"), ("posts", "fn"), ("pscale", "f"), ("psolved", "f"),
          ("free", "free"))  # fmt: skip
_INT = (("cols", "k"), ("sets", "fs"), ("wsi", "2(n+1)"), ("mask", "n"))
(_G, _B, _FW, _LIM, _BUF, _C, _P4, _PRM, _STATE, _P3, _ZM, _V, _LM, _Y, _Z, _NSS, _YS, _WSF, _GRAM,
 _WREL, _MWS, _QA, _HB, _ZS, _POSTS, _PSCALE, _PSOLVED, _FREE) = range(28)  # fmt: skip
_COLS, _SETS, _WSI, _MASK = range(4)
_HEAD = 8
_NF = len(_FLOAT)


_free_dims = getattr(free_shape, "py_func", free_shape)  # plain Python without numba


def _shapes(n, m, f, s, k) -> dict[str, tuple[int, ...]]:
    n1 = n + 1
    multi = m * m + m * n + n + 2 * s * s + 2 * s
    return {"mm": (m, m), "mn": (m, n), "n": (n,), "2n": (2, n), "4": (4,), "3n": (3, n),
            "2": (2,), "4n": (4, n), "n+2": (n + 2,), "3": (3,), "nn": (n, n), "7n": (7, n),
            "m": (m,), "ss": (s, s), "s": (s,), "8(n+1)": (8, n1), "(n+1)(n+1)": (n1, n1),
            "f": (f,), "multi": (multi,), "k": (k,), "fs": (f, s), "2(n+1)": (2, n1), "nm": (n, m),
            "fn": (f, n), "free": (2, *_free_dims(m, n))}  # fmt: skip


def workspace(n: int, m: int, sets: np.ndarray, cols: np.ndarray, mode: int):
    """``(F, Iw, views)``: the float and int buffers of :func:`free_then_bounded` and NumPy views of them.

    ``sets`` (f, s) int, −1 padded; ``cols`` the lockable columns (single-joint scenarios).
    """
    f, s = sets.shape
    k = len(cols)
    shapes = _shapes(n, m, f, s, k)
    sizes_f = [int(np.prod(shapes[code])) for _, code in _FLOAT]
    sizes_i = [int(np.prod(shapes[code])) for _, code in _INT]
    F = np.zeros(sum(sizes_f))
    Iw = np.zeros(_HEAD + len(_FLOAT) + len(_INT) + sum(sizes_i), dtype=np.int64)
    Iw[:6] = n, m, f, s, mode, k
    views: dict[str, np.ndarray] = {}
    o = 0
    for t, ((name, code), size) in enumerate(zip(_FLOAT, sizes_f, strict=True)):
        Iw[_HEAD + t] = o
        views[name] = F[o : o + size].reshape(shapes[code])
        o += size
    o = _HEAD + len(_FLOAT) + len(_INT)
    for t, ((name, code), size) in enumerate(zip(_INT, sizes_i, strict=True)):
        Iw[_HEAD + len(_FLOAT) + t] = o
        views[name] = Iw[o : o + size].reshape(shapes[code])
        o += size
    views["cols"][:] = cols
    views["sets"][:] = sets
    views["state"][0] = 1.0
    return F, Iw, views


@_inline
def _fv(F, Iw, t, r):  # pragma: no cover - numba
    o = Iw[_HEAD + t]
    return F[o : o + r]


@_inline
def _fm(F, Iw, t, r, c):  # pragma: no cover - numba
    o = Iw[_HEAD + t]
    return F[o : o + r * c].reshape((r, c))


@_inline
def _im(F, Iw, t, r, c):  # pragma: no cover - numba
    o = Iw[_HEAD + _NF + t]
    return Iw[o : o + r * c].reshape((r, c))


@_inline
def _iv(F, Iw, t, r):  # pragma: no cover - numba
    o = Iw[_HEAD + _NF + t]
    return Iw[o : o + r]


@_inline
def _reduced_box(
    J, Z, r, S, k, bound, params, W, target, p0, d, zr, lo, hi, qd, act, res
):  # pragma: no cover - numba
    """A reduced robot's rates nearest ``target`` under the box, by the dual active set (L6, L7).

    ``p₀ = Z_S Z_Sᵀ target`` (0: the least-norm response) and the rates ``p₀ + s d + Z_S u``,
    ``d`` its (G1) rates. Returns a code of the module doc (3: near ``J_S``'s singularity, left to
    the reference). ``target`` and ``p₀`` may be one array; ``zr`` (r,) scratch.
    """
    Zs, Gs, mask, ws, wsi, gram = W[0], W[3], W[4], W[5], W[6], W[7]
    if undamped(J, S, k, bound, params, Gs) != 0.0:  # near J_S's singularity, or undecided
        return 3
    rs = reduced_basis(Z, r, S, k, Zs, zr)
    if rs < 0:
        return 3
    n = Z.shape[0]
    least_norm = True
    for j in range(n):
        least_norm = least_norm and target[j] == 0.0
    if least_norm:  # p₀ = 0
        for j in range(n):
            p0[j] = 0.0
        return solve_box_rates(p0, d, Zs, rs, lo, hi, mask, qd, act, ws, wsi, gram, res, 1.0)
    null_project(Zs, rs, target, zr, p0)  # p₀ = N_S c = Z_S (Z_Sᵀ c)
    for t in range(k):
        p0[S[t]] = 0.0
    return solve_box_rates(p0, d, Zs, rs, lo, hi, mask, qd, act, ws, wsi, gram, res, 1.0)


@_inline
def _set_size(sets, sc) -> int:  # pragma: no cover - numba
    """The number of joints of scenario ``sc`` (its row of ``sets`` is −1 padded)."""
    k = 0
    while k < sets.shape[1] and sets[sc, k] >= 0:
        k += 1
    return k


@_inline
def _record_post(qd, S, k, sc, wrel, P, cbar, ps, pb, res) -> None:  # pragma: no cover - numba
    """A reduced robot's bounded rates ``qd`` (zeroed on ``S[:k]``) into row ``sc`` of ``P``.

    Its share ``w_S/W`` of them goes into ``cbar``, its scale ``res[0]`` into ``ps``;
    ``pb[sc] = res[1] = 1``.
    """
    for t in range(k):
        qd[S[t]] = 0.0
    for j in range(qd.shape[0]):
        P[sc, j] = qd[j]
        cbar[j] += wrel[sc] * qd[j]
    ps[sc], pb[sc], res[1] = res[0], 1.0, 1.0


@_inline_once
def _jvja_target(
    J, xdot, Z, r, V, tr, lo, hi, sets, wrel, params, W, res
):  # pragma: no cover - numba
    """``c = Σ_S (w_S/W) ˢq̇'_b`` (L4) into ``V[2]``; returns a code, ``res[1] = 1`` if a bound met.

    ``W = (Zs, NSS, ys, Gs, mask, ws, wsi, gram, P, ps, pb)``: scratch, and each ``ˢq̇'_b`` into
    row ``S`` of ``P``, its task scaling into ``ps`` and 1.0 into ``pb`` where it was solved under
    the box (the simulated sample's jump reads them).
    """
    NSS, ys, mask, P, ps, pb = W[1], W[2], W[4], W[8], W[9], W[10]
    n = Z.shape[0]
    f, s = sets.shape
    post, cbar, act, zr = V[1], V[2], V[5], V[6]
    for j in range(n):
        cbar[j] = 0.0
    for sc in range(f):
        k, S = _set_size(sets, sc), sets[sc]
        trinv = reduced_rates(Z, r, V[0], S, k, post, NSS, ys, params[1], zr)
        if trinv < 0.0:
            return 2
        inside = True
        for j in range(n):
            inside = inside and lo[j] - BOX_TOL <= post[j] <= hi[j] + BOX_TOL
        if inside:
            for j in range(n):
                P[sc, j] = min(max(post[j], lo[j]), hi[j])
                cbar[j] += wrel[sc] * P[sc, j]
            ps[sc], pb[sc] = 1.0, 0.0
            continue
        for j in range(n):
            mask[j] = 1
            V[3, j] = 0.0
        for t in range(k):
            mask[S[t]] = 0
        st = _reduced_box(J, Z, r, S, k, tr * trinv, params, W, V[3], V[3], post, zr, lo, hi,
                          V[4], act, res)  # fmt: skip
        if st:
            return st
        _record_post(V[4], S, k, sc, wrel, P, cbar, ps, pb, res)
    return 0


@_inline_once
def _mda_inside(out, lo, hi, state) -> bool:  # pragma: no cover - numba
    """MDA's own rates when they are inside the box (as the reference), clipped to it."""
    n = out.shape[0]
    for j in range(n):
        if not lo[j] - BOX_TOL <= out[j] <= hi[j] + BOX_TOL:
            return False
    for j in range(n):
        out[j] = min(max(out[j], lo[j]), hi[j])
        state[2 + j] = 0.0
    state[0] = 1.0
    return True


# The Controller's bounded step after its unbounded rates: (L2)-(L4) for LNVA, JVJA and MDA.
@_njit
def bounded_solve(J, xdot, out, mode, F, Iw):  # pragma: no cover - numba
    """Rates of ``mode`` (0 LNVA, 1 JVJA least-norm response, 2 MDA) in the box into ``out``.

    The box is ``buf[0], buf[1]`` of the workspace (:func:`workspace`; the box check writes it).
    MDA: ``out`` holds its unbounded rates on entry (their null-space part ``N (q̇ − a)`` is
    kept as the target, as in the reference). ``state[0]`` gets the task scaling, ``state[1]`` 1 when a bound was met,
    ``state[2:]`` 1.0 on joints held at a bound. Every objective's rates come from the dual active
    set (L7), JVJA's target from its reduced robots' (L4). Returns a code of the module doc (0:
    solved; otherwise ``out`` is untouched).
    """
    n, m, f, s = Iw[0], Iw[1], Iw[2], Iw[3]
    buf, state = _fm(F, Iw, _BUF, 4, n), _fv(F, Iw, _STATE, n + 2)
    lo, hi = buf[0], buf[1]
    Z, V, p3 = _fm(F, Iw, _ZM, n, n), _fm(F, Iw, _V, 7, n), _fv(F, Iw, _P3, 3)
    a, p0, qd, zr = V[0], V[3], V[4], V[6]
    Gs = _fm(F, Iw, _LM, m, m)
    st, tr = factor(J, xdot, Gs, _fm(F, Iw, _Y, m, n), _fv(F, Iw, _Z, m), a, p3)
    if st:
        return 1
    mask, ws, wsi = _iv(F, Iw, _MASK, n), _fm(F, Iw, _WSF, 8, n + 1), _im(F, Iw, _WSI, 2, n + 1)
    gram = _fm(F, Iw, _GRAM, n + 1, n + 1)
    res = state[:2]
    res[1] = 0.0
    if mode == 2 and _mda_inside(out, lo, hi, state):
        return 0
    r = null_basis(J, Z, _fm(F, Iw, _QA, n, m), _fv(F, Iw, _HB, m))
    if mode == 1:
        W = (_fm(F, Iw, _ZS, n, n), _fm(F, Iw, _NSS, s, s), _fv(F, Iw, _YS, s), Gs, mask, ws, wsi,
             gram, _fm(F, Iw, _POSTS, f, n), _fv(F, Iw, _PSCALE, f), _fv(F, Iw, _PSOLVED, f))  # fmt: skip
        st = _jvja_target(J, xdot, Z, r, V, tr, lo, hi, _im(F, Iw, _SETS, f, s), _fv(F, Iw, _WREL, f),
                          p3, W, res)  # fmt: skip
        if st:
            return st
        null_project(Z, r, V[2], zr, p0)  # p₀ = N c = Z (Zᵀ c)
    elif mode == 2:  # as the reference: N (q̇ − a) as the target
        for j in range(n):
            p0[j] = out[j] - a[j]
        null_project(Z, r, p0, zr, p0)  # p₀ = N (q̇ − a); the target is read before p₀ is written
    else:
        for j in range(n):
            p0[j] = 0.0
    bounded = res[1]
    for j in range(n):
        mask[j] = 1
    st = solve_box_rates(p0, a, Z, r, lo, hi, mask, qd, state[2:], ws, wsi, gram, res, 1.0)
    if st:
        return st
    res[1] = max(res[1], bounded)
    for j in range(n):
        out[j] = qd[j]
    return 0


@_njit
def free_then_bounded(J, q, xdot, out, F, Iw):  # pragma: no cover - numba
    """LNVA or single-joint JVJA under the box in one call: the free kernel, then the solve.

    :func:`fault_tolerance.control.fast.bounded_free.free_kernel` on its workspace, the section
    ``free[Iw[4]]`` of ``F`` (:func:`fault_tolerance.control.fast.bounded_free.free_workspace`),
    and, only when a bound is met, :func:`bounded_solve` in the box that kernel computed (the
    numbers the box check computes). Returns 0 (no bound
    met, ``out`` final), 1 (solved, a bound met), 2 (solved, none met) or 3 (refused: sizes, the
    unbounded step or the solve; the reference route).
    """
    n, m, mode = Iw[0], Iw[1], Iw[4]
    if mode < 0 or mode > 1:  # other sizes of J, q, ẋ, out: the free kernel's status 2
        return 3
    rows, width = free_shape(m, n)
    o = Iw[_HEAD + _FREE] + mode * rows * width
    W = F[o : o + rows * width].reshape((rows, width))
    state = _fv(F, Iw, _STATE, n + 2)
    st = _free(J, q, xdot, out, W, state)  # free_kernel, inlined
    if st != 1:
        return 0 if st == 0 else 3
    h = 4 + 2 * m
    buf = _fm(F, Iw, _BUF, 4, n)
    for j in range(n):  # the box (L1) the free kernel computed
        buf[0, j] = W[h + 3, j]
        buf[1, j] = W[h + 4, j]
    if bounded_solve(J, xdot, out, mode, F, Iw):
        return 3
    return 1 if state[1] != 0.0 else 2


# Eqn. (L4) for chosen reduced robots (the simulated sample's jump under the box).
@_njit
def reduced_solve(J, xdot, target, todo, post, scales, codes, F, Iw):  # pragma: no cover - numba
    """Bounded rates (L4) of the reduced robots ``todo`` into ``post`` (rows), scalings into ``scales``.

    As :func:`fault_tolerance.resolution.bounded.reduced_bounded` without a guess: ``min ‖q̇ − c‖²`` s.t.
    ``J_S q̇ = s ẋ`` in the box ``buf[0], buf[1]`` of the workspace, ``c = target`` (zeros: the
    least-norm rates). Near ``J_S``'s singularity the scenario is left to the reference (code 3),
    which solves it exactly without damping.
    ``codes[i]`` gets 0 (solved) or the module doc's code for scenario ``todo[i]`` (left to the
    reference). Returns 1 when ``J`` has no certificate (nothing solved), else 0.
    """
    n, m, f, s = Iw[0], Iw[1], Iw[2], Iw[3]
    buf, state = _fm(F, Iw, _BUF, 4, n), _fv(F, Iw, _STATE, n + 2)
    lo, hi = buf[0], buf[1]
    Z, V, p3 = _fm(F, Iw, _ZM, n, n), _fm(F, Iw, _V, 7, n), _fv(F, Iw, _P3, 3)
    a, d, p0, qd, act, zr = V[0], V[1], V[3], V[4], V[5], V[6]
    Gs = _fm(F, Iw, _LM, m, m)
    st, tr = factor(J, xdot, Gs, _fm(F, Iw, _Y, m, n), _fv(F, Iw, _Z, m), a, p3)
    if st:
        return 1
    r = null_basis(J, Z, _fm(F, Iw, _QA, n, m), _fv(F, Iw, _HB, m))
    mask, ws, wsi = _iv(F, Iw, _MASK, n), _fm(F, Iw, _WSF, 8, n + 1), _im(F, Iw, _WSI, 2, n + 1)
    gram, Zs = _fm(F, Iw, _GRAM, n + 1, n + 1), _fm(F, Iw, _ZS, n, n)
    NSS, ys, sets = _fm(F, Iw, _NSS, s, s), _fv(F, Iw, _YS, s), _im(F, Iw, _SETS, f, s)
    W = (Zs, NSS, ys, Gs, mask, ws, wsi, gram)
    res = state[:2]
    for i in range(todo.shape[0]):
        S = sets[todo[i]]
        k = 0
        while k < s and S[k] >= 0:
            k += 1
        trinv = reduced_rates(Z, r, a, S, k, d, NSS, ys, p3[1], zr)  # (G1): J_S⁺ẋ
        if trinv < 0.0:
            codes[i] = 2
            continue
        for j in range(n):
            mask[j] = 1
        for t in range(k):
            mask[S[t]] = 0
        st = _reduced_box(J, Z, r, S, k, tr * trinv, p3, W, target, p0, d, zr, lo, hi, qd, act,
                          res)  # fmt: skip
        codes[i] = st
        if st:
            continue
        for t in range(k):
            qd[S[t]] = 0.0
        for j in range(n):
            post[i, j] = qd[j]
        scales[i] = res[0]
    return 0


def _solve_mode(name: str) -> int:
    """The mode of :func:`bounded_solve` for resolver ``name`` (its entry's ``compiled``)."""
    from fault_tolerance.errors import InvalidInput
    from fault_tolerance.resolution.registry import get

    mode = get(name).compiled
    if mode not in (LNVA, JVJA, MDA):
        raise InvalidInput(f"resolver '{name}' has no compiled bounded solve")
    return mode


def bounded_rates(name: str, J, xdot, sets, lo, hi, *, weights=None, unbounded=None, params=None):
    """:func:`bounded_solve` on one problem (tests, and callers without a Controller).

    ``sets``: the scenarios (tuples of column indices); ``unbounded``: MDA's unbounded rates;
    ``params``: ``[TRACE_MAX, pivot threshold, rank coefficient]`` (default: the Controller's
    without ``tolerate``, with the rank test). Returns ``(code, qd, scale, active, bounded)``;
    ``qd`` is meaningful only for code 0 (see the module doc).

    Example:
        >>> import numpy as np
        >>> J = np.array([[1.0, 1.0, 1.0]])
        >>> code, qd, s, act, _ = bounded_rates("lnva", J, np.array([0.3]), [(0,)],
        ...                                     -np.ones(3), np.array([1.0, 1.0, 0.05]))
        >>> code, [round(float(v), 3) for v in qd], s, act.tolist()
        (0, [0.125, 0.125, 0.05], 1.0, [False, False, True])
    """
    from fault_tolerance.control.lapack_steps import TRACE_MAX
    from fault_tolerance.numerics.linalg import PIVOT_TOL

    J = np.ascontiguousarray(J, dtype=float)
    m, n = J.shape
    smax = max(len(S) for S in sets)
    table = -np.ones((len(sets), smax), dtype=np.int64)
    for k, S in enumerate(sets):
        table[k, : len(S)] = S
    mode = _solve_mode(name)
    F, Iw, views = workspace(n, m, table, np.zeros(0, dtype=np.int64), mode)
    w = np.ones(len(sets)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.max()  # scale-free; the sum cannot overflow
    views["wrel"][:] = w / w.sum()
    views["p3"][:] = [TRACE_MAX, PIVOT_TOL, RANK_RTOL**2] if params is None else params
    views["buf"][0], views["buf"][1] = lo, hi
    out = np.zeros(n) if unbounded is None else np.array(unbounded, dtype=float)
    code = bounded_solve(J, np.ascontiguousarray(xdot, dtype=float), out, mode, F, Iw)
    state = views["state"]
    return int(code), out, float(state[0]), state[2:] != 0.0, bool(state[1])
