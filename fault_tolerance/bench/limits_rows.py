"""Benchmark rows of the joint limits: the bounded JVJA step and a generic QP route.

* ``jvja_bounded_free``: ``Controller(limits=True)`` JVJA step where no bound is active (the fast
  step and the box check);
* ``jvja_bounded_2``: the same step where two joints are next to the limit they move towards, the
  box allowing 30 % of their unbounded rate (the task still reached, ``s = 1``): the bounded
  problem (L2) with the reduced robots' (L4), whose bounds meet the box too;
* ``jvja_bounded_2_qp``: that problem handed to quadprog: each reduced robot's bounded least-norm
  QP, then the bounded JVJA QP;
* ``jvja_unbounded_limits``: the unbounded JVJA step (the ``jvja`` row) timed again in this group's
  rounds, the denominator of the bounded rows' targets: both sides of a ratio are timed in the same
  rounds, so a change of the machine's speed between groups does not enter the ratio.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fault_tolerance.bench.routes import installed
from fault_tolerance.errors import FaultToleranceError

DESCRIPTIONS = {
    "jvja_bounded_free": "JVJA step with joint limits on, no bound active (fast step + box check)",
    "jvja_bounded_2": "JVJA step with joint limits on, two joints at a binding bound (bounded QPs)",
    "jvja_bounded_2_qp": "the same bounded JVJA problem by quadprog (f reduced QPs + 1)",
    "jvja_unbounded_limits": "the unbounded JVJA step, timed in the rounds of the joint-limit rows",
}


def _box_qp(H, c, J, xdot, lo, hi, keep):
    import quadprog

    Jk = J[:, keep]
    k = len(keep)
    C = np.hstack([Jk.T, np.eye(k), -np.eye(k)])
    b = np.concatenate([xdot, lo[keep], -hi[keep]])
    return quadprog.solve_qp(H[:k, :k], H[:k, :k] @ c[keep], C, b, J.shape[0])[0]


def jvja_bounded_qp(J, xdot, sc, lo, hi) -> np.ndarray:
    """Bounded JVJA (L2), least-norm response, with every QP solved by quadprog."""
    n = J.shape[1]
    eye, zero = np.eye(n), np.zeros(n)
    post = np.zeros((sc.f, n))
    for k, S in enumerate(sc.sets):
        keep = [j for j in range(n) if j not in S]
        post[k, keep] = _box_qp(eye, zero, J, xdot, lo, hi, keep)
    c = sc.weights @ post / sc.weights.sum()
    return _box_qp(eye, c, J, xdot, lo, hi, list(range(n)))


def _pools(case, ctrl):
    """``(q, ẋ)`` with no bound active, and with two joints at a binding bound (``s = 1``)."""
    arm, sc, h = case.arm, case.sc, ctrl.horizon
    free, two = [], []
    for q, xd in case.qx:
        for scale in (1.0, 0.3, 0.1, 0.03, 0.01):
            before = ctrl.bounded_steps
            ctrl.jvja(q, xd * scale)  # the pool is inside the limits: 0 is in the box, never empty
            if ctrl.bounded_steps == before:
                free.append((q, xd * scale))
                break
        try:
            pair = _two_bound_case(arm, sc, ctrl, q, xd * 0.05, h)
        except FaultToleranceError:  # a reduced robot intolerable there: not a bench case
            continue
        if pair is not None:
            two.append(pair)
    return free, two


def _two_bound_case(arm, sc, ctrl, q, xs, h):
    """``(q2, ẋ)`` with two joints next to the limit they move towards, or ``None``."""
    from fault_tolerance.resolution.api import resolve
    from fault_tolerance.resolution.bounded import resolve_bounded

    qd = resolve("jvja", arm.jacobian(q), xs, sc)
    top = np.argsort(-np.abs(qd))[:2]
    q2 = q.copy()
    for j in top:  # two joints next to the limit they move towards ...
        q2[j] = (arm.upper[j] - 0.002) if qd[j] > 0 else (arm.lower[j] + 0.002)
    qd2 = resolve("jvja", arm.jacobian(q2), xs, sc)
    for j in top:  # ... where the box allows 30 % of their unbounded rate
        limit = arm.upper[j] if qd2[j] > 0 else arm.lower[j]
        q2[j] = limit - 0.3 * qd2[j] * h
    if np.any((q2 < arm.lower) | (q2 > arm.upper)):
        return None
    q2 = np.ascontiguousarray(q2)
    if not _undamped(arm.jacobian(q2), sc):
        return None
    res = resolve_bounded("jvja", arm.jacobian(q2), xs, sc, bounds=arm.rate_bounds(q2, h))
    before = ctrl.bounded_steps
    ctrl.jvja(q2, xs)
    if ctrl.bounded_steps == before or res.scale < 1.0 or np.any(res.reduced_scale < 1.0):
        return None
    if installed("quadprog"):
        try:  # the generic route must solve the same problem (degenerate ones are left out)
            jvja_bounded_qp(ctrl.jacobian(q2), xs, sc, *arm.rate_bounds(q2, h))
        except ValueError:
            return None
    return q2, xs


def _undamped(J, sc) -> bool:
    """Whether ``J`` and every reduced Jacobian ``J_S`` are well away from the damping zone.

    Near it the reference damps a reduced robot (its rates then miss ``ẋ`` and still count as
    ``s = 1``): not the bounded problem this row times. The test is the problem's, so the pool is
    the same whether quadprog is installed or not (it refused those problems as inconsistent).
    """
    from fault_tolerance.numerics.linalg import SIGMA_EPS

    mats = [J] + [np.delete(J, list(S), axis=1) for S in sc.sets]
    return all(np.linalg.svd(M, compute_uv=False)[-1] >= 2.0 * SIGMA_EPS for M in mats)


def limits_rows(case) -> dict:
    """The rows above (``jvja_bounded_2*`` only where two-bound configurations were found)."""
    from fault_tolerance.control.controller import Controller

    ctrl = Controller(case.arm, case.spec["lockable"], backend=case.ctrl.backend)
    free, two = _pools(case, ctrl)
    out = case.out
    rows: dict[str, tuple[Callable[..., np.ndarray], list[tuple]]] = {}
    if free or two:
        rows["jvja_unbounded_limits"] = (case.ctrl.jvja, case.qxo)
    if free:
        rows["jvja_bounded_free"] = (ctrl.jvja, [(q, xd, out) for q, xd in free])
    if two:
        rows["jvja_bounded_2"] = (ctrl.jvja, [(q, xd, out) for q, xd in two])
        if installed("quadprog"):
            arm, sc = case.arm, case.sc
            args = [(q, xd) for q, xd in two]

            def qp(q, xd):
                lo, hi = arm.rate_bounds(q, ctrl.horizon)
                return jvja_bounded_qp(ctrl.jacobian(q), xd, sc, lo, hi)

            rows["jvja_bounded_2_qp"] = (qp, args)
    return rows
