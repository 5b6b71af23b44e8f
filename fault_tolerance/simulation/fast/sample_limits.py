"""The joint limits of a compiled simulated sample: the rate box (L1) and the servo's clip.

Used by :func:`fault_tolerance.simulation.fast.sample.sample_kernel` under joint limits: the box at ``q``
is built, and the planned rates checked against it, by the compiled box check of the
Controller's bounded step (:func:`fault_tolerance.control.fast.box_check.box_status`); the executed rates are
clipped at the position limits over one time step as ``reference_step._clip_to_limits``.
"""

from __future__ import annotations

from fault_tolerance.control.fast.box_check import g1_column_into
from fault_tolerance.fast_cache import inline as _inline
from fault_tolerance.fast_cache import inline as _inline_once
from fault_tolerance.numerics.fast.sample_dense import njit
from fault_tolerance.resolution.box_qp import BOX_TOL

try:  # the rate box check of the Controller's bounded step, compiled by numba
    from fault_tolerance.control.fast.box_check import compiled_box_status

    _box_status = compiled_box_status()
except ImportError:  # pragma: no cover - numba is a core dependency
    from fault_tolerance.control.fast.box_check import box_status as _box_status

#: The flag of a clipped servo (``run.FLAG_SERVO_CLIPPED``).
_FLAG_SERVO_CLIPPED = 256


@njit
def _in_box(q, lim, prm, buf, qd, P, Q, v, cols, locked) -> bool:  # pragma: no cover - numba
    """Box (L1) at ``q`` into ``buf[0], buf[1]`` (``box_status``); whether ``qd`` is inside it.

    Inside, ``qd`` is clipped into the box (``bounded.resolve_bounded`` does so). After a lock the
    locked joint (rate 0) is not checked: the reduced robot's box has no such joint.
    """
    n = qd.shape[0]
    lock = int(prm[2]) if locked else -1
    if _box_status(q, lim, prm, buf, qd, P, Q, v, cols, False) != 0:
        if lock < 0:
            return False
        for c in range(n):  # the locked joint's own bound does not count
            if c != lock and (qd[c] < buf[0, c] - BOX_TOL or qd[c] > buf[1, c] + BOX_TOL):
                return False
    for c in range(n):
        if c != lock:
            qd[c] = min(max(qd[c], buf[0, c]), buf[1, c])
    return True


@_inline_once
def _servo_clip(q, lim, dt, qd) -> int:  # pragma: no cover - numba
    """``reference_step._clip_to_limits``: the executed rates kept inside the limits over ``dt``."""
    flag = 0
    for c in range(qd.shape[0]):
        v = lim[2, c]
        lo = max((lim[0, c] - q[c]) / dt, -v)
        hi = min((lim[1, c] - q[c]) / dt, v)
        t = min(max(qd[c], lo), hi)
        if abs(t - qd[c]) > 1e-12:
            flag = _FLAG_SERVO_CLIPPED
        qd[c] = t
    return flag


# Eqn. (G1) / (G3): one reduced robot's rates from the kernel's factors.
@_inline
def g1_post(P, Q, base, piv, c, lo, hi, row, box) -> bool:  # pragma: no cover - numba
    """``row = base − (base_c / N_cc) N[c, :]`` (``N = I − PᵀQ``; ``row_c = 0``).

    The sample passes ``P = Q = Y = L⁻¹J`` (the Controller's compiled step's factor) and ``piv``
    its pivots ``N_cc`` by column. ``box``: returns whether ``row`` is inside ``[lo, hi]`` (to
    ``BOX_TOL``) and clips it into the box; else True, nothing clipped. The one copy of these
    rates in the compiled sample (its jumps and :func:`g1_posts`).
    """
    m, n = P.shape
    ratio = base[c] / piv[c]
    g1_column_into(P, Q, m, n, row, c)  # row[j] = N[j, c]
    ok = True
    for j in range(n):
        v = 0.0 if j == c else base[j] - ratio * row[j]
        if box:
            ok = ok and lo[j] - BOX_TOL <= v <= hi[j] + BOX_TOL
            v = min(max(v, lo[j]), hi[j])
        row[j] = v
    return ok


@_inline_once
def g1_posts(P, Q, base, piv, cols, lo, hi, post, inside) -> int:  # pragma: no cover - numba
    """Every reduced robot's :func:`g1_post` into the rows of ``post``, clipped into the box.

    ``inside[t]`` gets 1 when row ``t`` was inside the box ``[lo, hi]`` (to ``BOX_TOL``) before
    the clip, else 0; returns how many were not (they need the bounded solve (L4)).
    """
    out = 0
    for t in range(cols.shape[0]):
        ok = g1_post(P, Q, base, piv, cols[t], lo, hi, post[t], True)
        inside[t] = 1 if ok else 0
        out += 0 if ok else 1
    return out
