"""The box check (L1) of the Controller's bounded step: is the fast step inside the rate box?

:func:`box_status` (compiled by numba, also inside :mod:`fault_tolerance.control.fast.bounded_solve` and the
simulated sample's kernel) and :func:`box_status_numpy` (the lapack and numpy backends). Re-exported
by :mod:`fault_tolerance.control.bounded_step`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fault_tolerance.fast_cache import inline as _inline
from fault_tolerance.resolution.box_qp import BOX_TOL


# Eqn. (G1): the column N[:, i] of N = I - PᵀQ (never formed) that reduced robot i's rates
# a - (a_i / N_ii) N[:, i] need; the one copy of it in the compiled kernels.
@_inline
def g1_column_into(P, Q, m, n, col, i):  # pragma: no cover - numba
    """``col[j] = N[j, i]`` for ``j != i`` (``col[i]`` is ``N_ii - 1``); returns the pivot ``N_ii``.

    Summed row by row of ``P`` (the loops over ``j`` vectorise); with ``P = Q = Y`` the sums
    are those of ``N[i, j]`` entry by entry, bit for bit.
    """
    nii = 1.0
    for r in range(m):
        nii -= P[r, i] * Q[r, i]
    q0 = Q[0, i]
    for j in range(n):
        col[j] = 0.0 - P[0, j] * q0
    for r in range(1, m):
        qri = Q[r, i]
        for j in range(n):
            col[j] -= P[r, j] * qri
    return nii


def box_status(q, lim, prm, buf, out, P, Q, c, cols, jv):  # pragma: no cover - numba
    """Box (L1) at ``q`` into ``buf[0], buf[1]``; 0 when ``out`` (and, ``jv``, each (G1) rate) is inside.

    ``lim`` rows: lower, upper position limits, velocity limits; ``prm = [1/h, alpha]``; ``out =
    a + alpha N c`` is the JVJA step (``c`` its pivot ratios) with ``N = I - PᵀQ`` (the kernels
    never form N: ``P = Q = Y = L⁻¹J`` compiled, ``P = J, Q = G⁻¹J`` with LAPACK), so ``N[:, i] =
    e_i - Pᵀ Q[:, i]``; ``buf[2]`` and ``buf[3]`` (n each) are scratch. Plain Python with scalar
    loops (compiled by numba with the numba backend). Returns 1 when ``out`` leaves the box, 2 when
    a reduced robot's rates do.
    """
    n = q.shape[0]
    m = P.shape[0]
    lower, upper, vmax = lim[0], lim[1], lim[2]
    lo, hi, a, y = buf[0], buf[1], buf[2], buf[3]
    ih, alpha = prm[0], prm[1]
    bad = 0
    for j in range(n):
        lj = (lower[j] - q[j]) * ih
        hj = (upper[j] - q[j]) * ih
        v = vmax[j]
        lj = -v if lj < -v else (v if lj > v else lj)
        hj = -v if hj < -v else (v if hj > v else hj)
        lo[j] = lj
        hi[j] = hj
        if out[j] < lj - BOX_TOL or out[j] > hj + BOX_TOL:
            bad = 1
    if bad or not jv:
        return bad
    for r in range(m):  # N c = c - Pᵀ (Q c), N never formed
        s = 0.0
        for k in range(n):
            s += Q[r, k] * c[k]
        y[r] = s
    for j in range(n):  # the loops over j run along the rows of P (vectorised)
        a[j] = c[j]
    for r in range(m):
        yr = y[r]
        for j in range(n):
            a[j] -= P[r, j] * yr
    for j in range(n):
        a[j] = out[j] - alpha * a[j]
    for t in range(cols.shape[0]):
        i = int(cols[t])  # int, or a float holding one (the free kernel's workspace row)
        nii = g1_column_into(P, Q, m, n, y, i)  # y is spent: N[:, i]
        ratio = a[i] / nii
        for j in range(n):
            p = a[j] - ratio * y[j]
            if j != i and (p < lo[j] - BOX_TOL or p > hi[j] + BOX_TOL):
                return 2
    return 0


def box_status_numpy(q, lim, prm, buf, out, P, Q, c, cols, jv):
    """:func:`box_status` with NumPy array operations (the lapack and numpy backends)."""
    lower, upper, vmax = lim[0], lim[1], lim[2]
    lo, hi, a = buf[0], buf[1], buf[2]
    ih, alpha = prm[0], prm[1]
    np.subtract(lower, q, out=lo)
    np.multiply(lo, ih, out=lo)
    np.clip(lo, -vmax, vmax, out=lo)
    np.subtract(upper, q, out=hi)
    np.multiply(hi, ih, out=hi)
    np.clip(hi, -vmax, vmax, out=hi)
    if (out < lo - BOX_TOL).any() or (out > hi + BOX_TOL).any():
        return 1
    if not jv:
        return 0
    np.subtract(c, P.T @ (Q @ c), out=a)  # N c = c - Pᵀ (Q c)
    np.multiply(a, -alpha, out=a)
    np.add(a, out, out=a)
    k = np.arange(len(cols))
    Ncols = -(P.T @ Q[:, cols]).T  # row t: N[cols[t], :] (N symmetric)
    Ncols[k, cols] += 1.0
    post = a - (a[cols] / Ncols[k, cols])[:, None] * Ncols
    post[k, cols] = 0.0
    if (post < lo - BOX_TOL).any() or (post > hi + BOX_TOL).any():
        return 2
    return 0


_COMPILED: dict[str, Callable] = {}


def compiled_box_status() -> Callable:
    """:func:`box_status` compiled by numba (once per process; cached on disk)."""
    if "box" not in _COMPILED:
        from fault_tolerance.fast_cache import njit

        _COMPILED["box"] = njit(box_status)
    return _COMPILED["box"]


__all__ = ["box_status", "box_status_numpy", "compiled_box_status", "g1_column_into"]
