"""A simulated sample that meets a bound of the rate box, in one compiled call (before a lock).

:func:`fault_tolerance.simulation.fast.sample.sample_kernel` returns ``BOUNDED`` when the planned rates,
or a reduced robot's rates ``ˢq̇'``, leave the rate box (L1). :func:`bounded_sample` then does the
rest of the sample without coming back to Python, with the same compiled pieces the Python route
of :meth:`fault_tolerance.simulation.fast.sampler.Sampler._bounded` calls one by one:

* the planned rates: the kernel's own (clipped into the box) for LNVA when they are inside it,
  else the Controller's bounded solve (:func:`fault_tolerance.control.fast.bounded_solve.bounded_solve`, (L2)-(L4))
  in the box the kernel built;
* every reduced robot's rates under the box (L4) and their task scalings (L5): those JVJA's
  bounded step solved for its target (``ˢq̇'_b``, the same problems), or else (G1)/(G3) from the
  kernel's factors where they are inside the box (:func:`fault_tolerance.simulation.fast.sample_limits.g1_posts`)
  and the compiled bounded solve :func:`fault_tolerance.control.fast.bounded_solve.reduced_solve` for the others;
* the jump parts ``w_S ‖ˢq̇'_b − q̇‖²``, the flags, and the end of the sample
  (``sample_kernel._finish``: indices, servo, record, ``q ← q + q̇ dt``).

It returns :data:`DECLINED` (and has changed nothing the Python route reads) where any of these
refuses: the Python route then takes the sample and its fallbacks to the reference code. MDA and
the samples after a lock always take the Python route. :func:`limited_sample` is the sample
kernel and this in one call (what :class:`~fault_tolerance.simulation.fast.sampler.Sampler` runs under joint
limits). Plain Python without numba.
"""

from __future__ import annotations

import numpy as np

from fault_tolerance.control.fast.bounded_solve import (
    _BUF,
    _POSTS,
    _PSCALE,
    _PSOLVED,
    _STATE,
    _fm,
    _fv,
    bounded_solve,
    reduced_solve,
)
from fault_tolerance.numerics.fast.sample_dense import P_CONT, njit
from fault_tolerance.resolution.bounded import SCALE_TOL
from fault_tolerance.simulation.fast.sample import (
    BOUNDED,
    JVJA,
    LNVA,
    O_PARTS,
    _finish,
    _views,
    sample_kernel,
)
from fault_tolerance.simulation.fast.sample_limits import g1_posts

#: Returned when the compiled code refuses a part: the caller takes the Python route.
DECLINED = -3
#: ``run.FLAG_BOUND_ACTIVE``, ``run.FLAG_TASK_SCALED``, ``run.FLAG_INTOLERABLE_UNDER_LIMITS``.
FLAG_BOUND_ACTIVE, FLAG_TASK_SCALED, FLAG_INTOLERABLE_UNDER_LIMITS = 32, 64, 128


def own_workspace(F0: np.ndarray, I0: np.ndarray, mode: int) -> tuple:
    """``(F, Iw, views)``: a copy of a Controller's bounded-step workspace, in ``mode``.

    The one-call sample solves in its own copy, so it never disturbs the Controller's state
    (``last_scale``, ``last_active``) that the Python route reads.
    """
    from fault_tolerance.control.fast.bounded_solve import _FLOAT, _HEAD, _shapes

    F, Iw = F0.copy(), I0.copy()
    Iw[4] = mode
    n, m, f, s, _, k = (int(v) for v in Iw[:6])
    shapes = _shapes(n, m, f, s, k)
    views = {}
    for t, (name, code) in enumerate(_FLOAT):
        o, shape = int(Iw[_HEAD + t]), shapes[code]
        views[name] = F[o : o + int(np.prod(shape))].reshape(shape)
    return F, Iw, views


def scratch(f: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(TF, TI)``: the float and int scratch of :func:`bounded_sample` (see :func:`_tables`).

    ``TI[3 f : 3 f + 3]`` is ``info``.
    """
    return np.zeros(2 * f * n + 2 * f + n), np.zeros(3 * f + 3, dtype=np.int64)


@njit
def _tables(TF, TI, f, n):  # pragma: no cover - numba
    """``post, scales, rpost, rscale, target`` in ``TF``; ``inside, codes, todo, info`` in ``TI``."""
    post, rpost = TF[: f * n].reshape((f, n)), TF[f * n : 2 * f * n].reshape((f, n))
    o = 2 * f * n
    return (post, TF[o : o + f], rpost, TF[o + f : o + 2 * f], TF[o + 2 * f : o + 2 * f + n],
            TI[:f], TI[f : 2 * f], TI[2 * f : 3 * f], TI[3 * f : 3 * f + 3])  # fmt: skip


@njit
def _planned(J, xd, ws, method, buf, F, Iw, info) -> int:  # pragma: no cover - numba
    """Planned rates into the kernel's ``qd`` and their flags; -1 when the bounded step refuses.

    ``F, Iw``: the bounded step's workspace (a copy of the Controller's, :func:`own_workspace`):
    its box gets the kernel's ``buf``; its ``state`` has the task scale and the joints held at a
    bound, its ``posts`` the reduced robots' rates under the box of JVJA's target. A refused
    solve leaves ``qd`` as the kernel left it.
    """
    m, n = J.shape
    qd = _views(ws, m, n)[8]
    if ws[-2] > 0.0 and method != JVJA:  # W_INSIDE: the kernel's rates, clipped into the box
        return int(ws[-3])
    state, fbuf = _fv(F, Iw, _STATE, n + 2), _fm(F, Iw, _BUF, 4, n)
    for c in range(n):  # the kernel's box (the same limits and horizon as the Controller's)
        fbuf[0, c], fbuf[1, c] = buf[0, c], buf[1, c]
    if bounded_solve(J, xd, qd, 1 if method == JVJA else 0, F, Iw):
        return -1
    info[0] = 1 if state[1] != 0.0 else 0  # solved as the bounded problem (bounded_steps)
    flag = FLAG_TASK_SCALED if state[0] < 1.0 - SCALE_TOL else 0
    for c in range(n):
        if state[2 + c] != 0.0:
            return flag | FLAG_BOUND_ACTIVE
    return flag


@njit
def _posts(J, xd, ws, cols, buf, qcmd, cont, F, Iw, tabs) -> bool:  # pragma: no cover - numba
    """Every reduced robot's rates under the box into ``post`` (rows), scalings into ``scales``.

    ``F, Iw``: the reduced robots' workspace of ``boxsolve``; ``tabs`` :func:`_tables`'s.
    False: refused.
    """
    m, n = J.shape
    f = cols.shape[0]
    post, scales, rpost, rscale, target, inside, codes, todo, info = tabs
    B, a, piv = _views(ws, m, n)[3], _views(ws, m, n)[4], _views(ws, m, n)[7]
    base = qcmd if cont else a
    for t in range(f):
        scales[t] = 1.0
    if g1_posts(B, B, base, piv, cols, buf[0], buf[1], post, inside) == 0:
        return True
    nt = 0
    for t in range(f):
        if inside[t] == 0:
            todo[nt] = t
            nt += 1
    rbuf = _fm(F, Iw, _BUF, 4, n)
    for c in range(n):
        rbuf[0, c], rbuf[1, c] = buf[0, c], buf[1, c]
        target[c] = qcmd[c] if cont else 0.0
    if reduced_solve(J, xd, target, todo[:nt], rpost, rscale, codes[:nt], F, Iw):
        return False
    for i in range(nt):
        if codes[i] != 0:
            return False
    for i in range(nt):
        t = todo[i]
        for c in range(n):
            post[t, c] = rpost[i, c]
        scales[t] = rscale[i]
    info[1] = nt
    return True


@njit
def bounded_sample(
    J,
    xd,
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
    buf,
    F,
    Iw,
    F2,
    Iw2,
    TF,
    TI,
) -> int:  # pragma: no cover - numba
    """Sample ``k`` after :func:`~fault_tolerance.simulation.fast.sample.sample_kernel` returned ``BOUNDED``.

    The arguments are the kernel's (``buf`` holds the box it built), then the bounded step's
    workspace ``F, Iw`` (:func:`own_workspace`), the reduced robots' ``F2, Iw2`` and the scratch
    ``TF, TI`` (:func:`scratch`); ``info`` gets ``[bounded step solved (1) or not (0), reduced
    robots solved, 1]``. Returns the sample's flags, ``REFERENCE`` from the end of the sample, or
    :data:`DECLINED`.
    """  # fmt: skip
    m, n = J.shape
    f = cols.shape[0]
    tabs = _tables(TF, TI, f, n)
    info = tabs[8]
    info[0], info[1], info[2] = 0, 0, 1
    flag = _planned(J, xd, ws, method, buf, F, Iw, info)
    if flag < 0:
        return DECLINED
    qd = _views(ws, m, n)[8]
    post, scales = tabs[0], tabs[1]
    if method == JVJA and info[0] == 1:  # JVJA's target solved every reduced robot under the box
        post, scales = _fm(F, Iw, _POSTS, f, n), _fv(F, Iw, _PSCALE, f)
        solved = _fv(F, Iw, _PSOLVED, f)
        for t in range(f):
            info[1] += int(solved[t])
    elif not _posts(J, xd, ws, cols, buf, qd, params[P_CONT] > 0.0, F2, Iw2, tabs):
        return DECLINED
    row = T[k]
    jv = 0.0
    for t in range(f):
        acc = 0.0
        for c in range(n):
            e = post[t, c] - qd[c]
            acc += e * e
        row[off[O_PARTS] + t] = w[t] * acc
        jv += w[t] * acc
        if scales[t] < 1.0 - SCALE_TOL:
            flag |= FLAG_INTOLERABLE_UNDER_LIMITS
    ws[-1] = jv
    return _finish(J, q, qd_prev, x, x_des, err, cols, vmax, params, method, k, row, off, ws, lim,
                   flag)  # fmt: skip


@njit
def limited_sample(
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
    F,
    Iw,
    F2,
    Iw2,
    TF,
    TI,
) -> int:  # pragma: no cover - numba
    """The sample kernel, then :func:`bounded_sample` in the same call when a bound is met.

    :func:`~fault_tolerance.simulation.fast.sample.sample_kernel` first; for LNVA and JVJA a ``BOUNDED``
    sample goes on to :func:`bounded_sample` (``info[2]`` = 1 then, else 0). The arguments are
    the kernel's, then :func:`bounded_sample`'s tables. ``BOUNDED`` is returned for the other
    methods (MDA, after a lock): the caller solves those.
    """  # fmt: skip
    TI[3 * cols.shape[0] + 2] = 0  # info[2]
    flag = sample_kernel(J, xd, qd_in, grad, q, qd_prev, x, x_des, err, cols, w, vmax, params,
                         method, k, T, off, ws, lim, prm, buf)  # fmt: skip
    if flag != BOUNDED or (method != JVJA and method != LNVA):
        return flag
    return bounded_sample(J, xd, q, qd_prev, x, x_des, err, cols, w, vmax, params, method, k, T,
                          off, ws, lim, buf, F, Iw, F2, Iw2, TF, TI)  # fmt: skip
