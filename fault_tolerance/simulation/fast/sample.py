"""One simulated sample after the Jacobian, in one compiled kernel: rates, λ parts, k_S, σ_min, flags.

:func:`sample_kernel` is what :func:`fault_tolerance.simulation.simulate.simulate` runs at every sample
(through :class:`fault_tolerance.simulation.fast.sampler.Sampler`): from the task Jacobian ``J`` and the commanded
task velocity it computes, with one Cholesky factorisation ``G = J Jᵀ = L Lᵀ`` and never the n x n
projector ``N`` itself (only ``Y = L⁻¹J``, ``N = I − YᵀY``: its diagonal and its products with
vectors ``N v = v − Yᵀ(Y v)``):

* the rates, by the Controller's compiled steps' own kernels (inlined, one compiled copy of each
  formula): LNVA ``a = J⁺ẋ`` and JVJA in closed form (G2) ``a + alpha N c``
  (:func:`fault_tolerance.control.fast.step.jvja_factors`, :func:`~fault_tolerance.control.fast.step.jvja_rates`);
  MDA ``a - α N ∇K`` (``∇K`` given, the step capped,
  :func:`fault_tolerance.control.fast.mda_step.null_step`); rates given by the caller; or, after a
  lock, the least-norm rates of the remaining joints (the step's ``_lnva``);
* the jump each scenario would cause now, ``w_S ‖ˢq̇' − q̇‖²`` (eqs. 9/10; ``ˢq̇'`` by G1, least-norm or
  continuation response, G3);
* the reduced condition numbers ``k_S`` (eq. 15) from the extreme eigenvalues of ``J_S J_Sᵀ = G −
  J_i J_iᵀ`` (secular equations on one eigenbasis of ``G``, :mod:`fault_tolerance.numerics.fast.rank_one_eigen`),
  their square sum ``K`` and ``σ_min(J)``;
* the flags of :mod:`fault_tolerance.simulation.run` it can decide (locked, step-limited, over-speed,
  servo-clipped).

Under joint limits (``params[P_BOUNDED]``) the sample is the bounded one while no bound is met:
the rate box (L1) at ``q`` is built and the rates checked against it by
:func:`fault_tolerance.control.fast.box_check.box_status`, every reduced robot's rates ``ˢq̇'`` (G1/G3) too
(the targets of the bounded resolvers and of the jump under limits, (L4)-(L5)); inside the box
the bounded resolvers return these very rates (clipped into the box within ``BOX_TOL``, as
:mod:`fault_tolerance.resolution.bounded` does), and the servo's rates are clipped at the position limits
as ``reference_step._clip_to_limits``.

It returns :data:`REFERENCE` (-1) when the sample needs the reference code instead: no
certificate that ``σ_min ≥ SIGMA_EPS`` (the reference damps there), a pivot ``N_ii`` below
``PIVOT_EPS`` (the reference damps and flags it), or numbers that are not finite; and
:data:`BOUNDED` (-2) when a bound is met (the caller solves the bounded problem). Plain Python,
valid without numba (and tested so); compiled by :func:`compiled_sample_kernel`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from fault_tolerance.control.fast.mda_step import null_step
from fault_tolerance.control.fast.step import _lnva, jvja_factors, jvja_rates
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.numerics.fast.dense import gram_into
from fault_tolerance.numerics.fast.sample_dense import (
    P_ACCEL,
    P_ALPHA,
    P_BOUNDED,
    P_CONT,
    P_DECAY,
    P_DT,
    P_GAIN,
    P_LOCK,
    P_MAXSTEP,
    P_RCN_MAX,
    P_TRACE,
    _cholesky,
    _downdate,
    _spectra,
    _trace_inverse,
    njit,
)
from fault_tolerance.simulation.fast.sample_limits import _in_box, _servo_clip, g1_post

#: ``method`` codes of :func:`sample_kernel`.
LNVA, JVJA, MDA, GIVEN, LOCKED = 0, 1, 2, 3, 4
#: What :func:`sample_kernel` returns instead of the flags: do the sample the reference way, or
#: solve it as the bounded problem (a bound of the rate box is met).
REFERENCE, BOUNDED = -1, -2
#: Indices into ``off``, the first column of each history in the run table (``simulation``).
COLUMNS = ("q", "qd", "qd_cmd", "x", "x_des", "error", "jvj", "jvj_parts", "rcn", "K",
           "sigma_min", "flags")  # fmt: skip
O_Q, O_QD, O_QCMD, O_X, O_XDES, O_ERROR, O_JVJ, O_PARTS, O_RCN, O_K, O_SIGMA, O_FLAGS = range(12)

_FLAG_LOCKED, _FLAG_STEP_LIMITED, _FLAG_OVER_SPEED = 4, 8, 16


@_inline_once
def _planned(Y, a, c, params, method, qd_in, grad, qd, Nv, u) -> int:  # pragma: no cover - numba
    """The rates of ``method`` into ``qd``; returns FLAG_STEP_LIMITED or 0.

    JVJA and MDA by the Controller's compiled steps' own kernels (:func:`.step.jvja_rates`,
    :func:`.mda_step.null_step`) from the factors of :func:`.step.jvja_factors` (``Y = L⁻¹J``,
    ``a``, the pivot ratios ``c``).
    """
    n = Y.shape[1]
    if method == LNVA:
        for i in range(n):
            qd[i] = a[i]
    elif method == JVJA:  # (G2): a + alpha N c, c_i = (w_i/W) a_i / N_ii
        jvja_rates(Y, a, qd, c, u, params[P_ALPHA], n)
    elif method == MDA:  # a - α N ∇K, the step capped at max_step (planner.mda)
        for i in range(n):
            Nv[i] = grad[i]
        null_step(Y, a, qd, Nv, u, params[P_GAIN], params[P_MAXSTEP], n)
        t = 0.0
        for i in range(n):
            t += (qd[i] - a[i]) * (qd[i] - a[i])
        if math.sqrt(t) >= 0.999 * params[P_MAXSTEP]:
            return _FLAG_STEP_LIMITED
    else:
        for i in range(n):
            qd[i] = qd_in[i]
    return 0


@_inline_once
def _jumps(Y, a, qd, piv, cols, w, cont, parts, box, row) -> float:  # pragma: no cover - numba
    """``w_S ‖ˢq̇' − q̇‖²`` of every scenario into ``parts`` (eqs. 9/10, G1/G3); their sum.

    ``ˢq̇'`` by :func:`.sample_limits.g1_post` (``N = I − YᵀY``, ``Y = L⁻¹J``, ``piv`` its
    diagonal by column) into ``row`` (n, scratch). ``box = (lo, hi, bounded)``: with ``bounded``
    each ``ˢq̇'`` is checked against the box ``[lo, hi]`` (L4) and clipped into it as
    ``bounded.reduced_bounded``; -1.0 when one leaves it (the reduced robot meets a bound).
    """
    n = Y.shape[1]
    lo, hi, bounded = box
    base = qd if cont else a
    total = 0.0
    for k in range(cols.shape[0]):
        if not g1_post(Y, Y, base, piv, cols[k], lo, hi, row, bounded):
            return -1.0
        acc = 0.0
        for c in range(n):
            e = row[c] - qd[c]
            acc += e * e
        parts[k] = w[k] * acc
        total += parts[k]
    return total


@njit
def _locked(J, xd, G, params, Wm, L, y, z, qd) -> bool:  # pragma: no cover - numba
    """Least-norm rates of the joints left after the lock, ``G_r = G − J_l J_lᵀ``; False: reference.

    The rates by the Controller's compiled LNVA (:func:`.step._lnva`: ``J_rᵀ G_r⁻¹ ẋ``; the
    locked column's rate is then 0).
    """
    m = J.shape[0]
    lock = int(params[P_LOCK])
    _downdate(G, J, lock, Wm)  # G_r = J_r J_rᵀ, the joints left
    if not _cholesky(Wm, L, m) or not _trace_inverse(L, z, m) <= params[P_TRACE]:
        return False
    _lnva(J, xd, qd, L, y)
    qd[lock] = 0.0
    return True


@_inline_once
def _follow(qd_cmd, qd_prev, params, k, locked, out) -> None:  # pragma: no cover - numba
    """Actual rates one step later, as ``simulation.ServoModel.follow`` (a locked joint stops)."""
    decay, step = params[P_DECAY], params[P_ACCEL]
    for c in range(qd_cmd.shape[0]):
        t = qd_cmd[c]
        if k > 0:
            if decay >= 0.0:
                t = qd_cmd[c] + (qd_prev[c] - qd_cmd[c]) * decay
            if step < math.inf:
                t = qd_prev[c] + min(max(t - qd_prev[c], -step), step)
        out[c] = t
    if locked:
        out[int(params[P_LOCK])] = 0.0


@_inline_once
def _gram(J, G) -> None:  # pragma: no cover - numba
    """``G = J Jᵀ`` (both triangles): :func:`.dense.gram_into`'s lower triangle, mirrored."""
    gram_into(J, G)
    m = J.shape[0]
    for i in range(m):
        for j in range(i):
            G[j, i] = G[i, j]


@_inline_once
def _rates(
    J, xd, qd_in, grad, q, cols, w, params, method, parts, box, ws
) -> int:  # pragma: no cover
    """Rates into ``ws``'s ``qd``, the jumps into ``parts``; the flags so far, or -1 / -2.

    ``box = (lim, prm, buf)`` of :func:`_in_box` (used when ``params[P_BOUNDED]``).
    """
    m, n = J.shape
    f = cols.shape[0]
    G, L, Wm, B, a, v, Nv, piv, qd, y, z = _views(ws, m, n)
    lim, prm, buf = box
    bounded = params[P_BOUNDED] > 0.0
    _gram(J, G)  # kept (the indices' eigenbasis, the lock's downdate); its factor in L
    if method == LOCKED:
        if not _locked(J, xd, G, params, Wm, L, y, z, qd):
            return REFERENCE
        ws[-3], ws[-2] = _FLAG_LOCKED, 0.0
        if bounded and not _in_box(q, lim, prm, buf, qd, J, B, v, cols, True):
            return BOUNDED
        ws[-2] = 1.0
        for i in range(f):
            parts[i] = 0.0
        ws[-1] = 0.0
        return _FLAG_LOCKED
    if not _cholesky(G, L, m):  # G = L Lᵀ, certified by trace(G⁻¹) ≤ TRACE_MAX as the steps
        return REFERENCE
    tr = _trace_inverse(L, z, m)
    # the Controller's JVJA step's factors: Y = L⁻¹J (in B), a, pivots N_ii (piv), ratios (v)
    if not tr <= params[P_TRACE] or jvja_factors(J, xd, a, L, B, v, piv, _fw(ws, m, n), params, tr):
        return REFERENCE
    flag = _planned(B, a, v, params, method, qd_in, grad, qd, Nv, y)
    ws[-3], ws[-2] = flag, 0.0
    if bounded and not _in_box(q, lim, prm, buf, qd, B, B, v, cols, False):
        return BOUNDED
    ws[-2] = 1.0
    jv = _jumps(B, a, qd, piv, cols, w, params[P_CONT] > 0.0, parts, (buf[0], buf[1], bounded), Nv)
    if jv < 0.0:
        return BOUNDED
    ws[-1] = jv
    return flag


@njit
def _views(ws, m, n):  # pragma: no cover - numba
    """``G, L, Wm`` (m, m), ``B`` (m, n), ``a, v, Nv, piv, qd`` (n), ``y, z`` (m) in ``ws``."""
    G = ws[0 : m * m].reshape((m, m))
    L = ws[m * m : 2 * m * m].reshape((m, m))
    Wm = ws[2 * m * m : 3 * m * m].reshape((m, m))
    o = 3 * m * m
    B = ws[o : o + m * n].reshape((m, n))
    o += m * n
    a, v, Nv = ws[o : o + n], ws[o + n : o + 2 * n], ws[o + 2 * n : o + 3 * n]
    piv, qd = ws[o + 3 * n : o + 4 * n], ws[o + 4 * n : o + 5 * n]
    o += 5 * n
    return G, L, Wm, B, a, v, Nv, piv, qd, ws[o : o + m], ws[o + m : o + 2 * m]


@_inline_once
def _eigen_scratch(ws, m, n):  # pragma: no cover - numba
    """The ``m² + 5 m`` numbers of ``ws`` after :func:`_views`' that ``_spectra`` works in."""
    o = 3 * m * m + m * n + 5 * n + 2 * m
    return ws[o : o + m * m + 5 * m]


@_inline_once
def _fw(ws, m, n):  # pragma: no cover - numba
    """The Controller's scenario table ``fw`` (2, n) in ``ws`` (:func:`set_scenarios`)."""
    o = 4 * m * m + m * n + 5 * n + 7 * m
    return ws[o : o + 2 * n].reshape((2, n))


@njit
def sample_kernel(
    J,
    xd,
    qd_in,
    grad,
    q,
    qd_prev,
    x,
    x_des,
    err,
    cols,
    w,
    vmax,
    params,
    method,
    k,
    T,
    off,
    ws,
    lim,
    prm,
    buf,
) -> int:  # pragma: no cover - numba
    """Sample ``k`` after the Jacobian into row ``k`` of the run table ``T``; the flags, or -1 / -2.

    ``J`` (m, n); ``xd`` the commanded task velocity; ``qd_in`` the rates for ``GIVEN``; ``grad``
    ``∇K`` for ``MDA``; ``q``, ``qd_prev`` the configuration and the actual rates so far (``q`` is
    advanced in place by ``q̇ dt``); ``x``, ``x_des``, ``err`` the task position, its target and
    error; ``cols`` the lockable column of each scenario, ``w`` their weights; ``vmax`` the joint
    velocity limits (inf: none); ``params`` see ``P_*``; ``method`` one of ``LNVA, JVJA, MDA,
    GIVEN, LOCKED``; ``T`` the run table and ``off`` its column offsets (``O_*``); ``ws`` a float
    workspace of :func:`workspace_size` numbers; under joint limits (``params[P_BOUNDED]``) ``lim``
    (3, n) the lower and upper position limits (±inf: none) and the velocity limits, ``prm =
    [1/h, 0, lock]``, ``buf`` (4, n) scratch (the box goes to ``buf[0], buf[1]``). -1
    (:data:`REFERENCE`): nothing usable was written, ``q`` is unchanged. -2 (:data:`BOUNDED`): a
    bound is met; ``ws`` holds the factors, ``a``, the planned rates and ``W_*``, the box is in
    ``buf``; the caller solves the bounded problem and ends the sample with
    :func:`finish_kernel`.
    """  # fmt: skip
    f = cols.shape[0]
    row = T[k]
    parts = row[off[O_PARTS] : off[O_PARTS] + f]
    flag = _rates(J, xd, qd_in, grad, q, cols, w, params, method, parts, (lim, prm, buf), ws)
    if flag < 0:
        return flag
    return _finish(
        J, q, qd_prev, x, x_des, err, cols, vmax, params, method, k, row, off, ws, lim, flag
    )


@njit
def finish_kernel(
    J, q, qd_prev, x, x_des, err, cols, vmax, params, method, k, T, off, ws, lim, qd_cmd, jv, flag
) -> int:  # pragma: no cover - numba
    """The rest of sample ``k`` after :func:`sample_kernel` returned :data:`BOUNDED`.

    The caller solved the bounded problem: ``qd_cmd`` the commanded rates, ``jv`` the jump (its
    parts already in the row), ``flag`` the flags so far. ``ws`` is the kernel's, as it left it.
    """
    m, n = J.shape
    qd = _views(ws, m, n)[8]
    for c in range(n):
        qd[c] = qd_cmd[c]
    ws[-1] = jv
    return _finish(
        J, q, qd_prev, x, x_des, err, cols, vmax, params, method, k, T[k], off, ws, lim, flag
    )


@njit
def _finish(
    J, q, qd_prev, x, x_des, err, cols, vmax, params, method, k, row, off, ws, lim, flag
) -> int:  # pragma: no cover - numba
    """Over-speed, ``k_S``, ``K``, ``σ_min``, the servo (clipped under limits), the row, ``q``."""
    m, n = J.shape
    f = cols.shape[0]
    G, L, Wm, B, a, v, Nv, piv, qd, y, z = _views(ws, m, n)
    total = 0.0
    for c in range(n):
        total += qd[c] * qd[c]
        if abs(qd[c]) > vmax[c]:
            flag |= _FLAG_OVER_SPEED
    if not total < math.inf:
        return REFERENCE
    ks = row[off[O_RCN] : off[O_RCN] + f]
    scratch = _eigen_scratch(ws, m, n)
    row[off[O_K]], row[off[O_SIGMA]] = _spectra(G, J, cols, ks, Wm, params[P_RCN_MAX], scratch)
    qd_row = row[off[O_QD] : off[O_QD] + n]
    _follow(qd, qd_prev, params, k, method == LOCKED, qd_row)
    if params[P_BOUNDED] > 0.0:
        flag |= _servo_clip(q, lim, params[P_DT], qd_row)
    _write(row, off, q, qd, x, x_des, err, params[P_DT], ws[-1], flag)
    return flag


@njit
def _write(row, off, q, qd, x, x_des, err, dt, jv, flag) -> None:  # pragma: no cover - numba
    """The rest of the sample's row; then ``q ← q + q̇ dt`` with the executed rates."""
    m, n = x.shape[0], q.shape[0]
    e = 0.0
    for i in range(m):
        row[off[O_X] + i] = x[i]
        row[off[O_XDES] + i] = x_des[i]
        e += err[i] * err[i]
    for c in range(n):
        row[off[O_Q] + c] = q[c]
        row[off[O_QCMD] + c] = qd[c]
        q[c] += row[off[O_QD] + c] * dt
    row[off[O_ERROR]] = math.sqrt(e)
    row[off[O_JVJ]] = jv
    row[off[O_FLAGS]] = flag


#: The last entries of the workspace: the planned rates' flags, whether they are inside the box
#: (1.0; then clipped into it in ``qd``), the jump.
W_FLAG, W_INSIDE, W_JUMP = -3, -2, -1


def workspace_size(m: int, n: int) -> int:
    """Length of the float workspace ``ws`` of :func:`sample_kernel` (see ``W_*``)."""
    return 4 * m * m + m * n + 7 * n + 7 * m + 3


def set_scenarios(ws, m: int, n: int, fw) -> None:
    """Put a Controller workspace's scenario table ``fw`` into ``ws``.

    ``ControllerWorkspace.fw``: 0 on lockable columns and +inf elsewhere, the weights ``w_i/W``
    or 1; ``params[P_ALPHA]`` takes its ``alpha``. The JVJA rates are then the Controller's
    compiled step's, number for number.
    """
    getattr(_fw, "py_func", _fw)(ws, m, n)[:] = fw


def compiled_sample_kernel() -> Callable:
    """:func:`sample_kernel` compiled by numba; ImportError without numba."""
    import numba  # noqa: F401 - raises ImportError here when numba is missing

    return sample_kernel
