"""One sample of a run the reference way: the plain planner, indices and bounded resolvers.

:func:`_step` is what :func:`fault_tolerance.simulation.simulate.simulate` does at a sample the compiled
sample (:mod:`fault_tolerance.simulation.fast.sampler`) does not cover, and at every sample with
``engine="reference"``: the rates at ``q`` (bounded under joint limits, (L1)-(L5)), the jump each
scenario would cause (eqs. 9/10), the reduced condition numbers (eq. 15), the flags, the servo,
the record, then ``q ← q + q̇ dt``.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from fault_tolerance.model.joint_limits import NO_LIMIT, arm_rate_box
from fault_tolerance.numerics.linalg import PIVOT_EPS, SIGMA_EPS, projection
from fault_tolerance.resolution.bounded import SCALE_TOL, bounded_least_norm, resolve_bounded
from fault_tolerance.resolution.indices import (
    condition_numbers,
    post_failure_rates,
    reduced_singular_values,
)
from fault_tolerance.resolution.limits import post_failure_under_limits
from fault_tolerance.resolution.resolvers import resolve
from fault_tolerance.simulation.run import (
    FLAG_BOUND_ACTIVE,
    FLAG_INTOLERABLE_UNDER_LIMITS,
    FLAG_LOCKED,
    FLAG_NEAR_INTOLERABLE,
    FLAG_NEAR_SINGULAR,
    FLAG_OVER_SPEED,
    FLAG_SERVO_CLIPPED,
    FLAG_STEP_LIMITED,
    FLAG_TASK_SCALED,
)
from fault_tolerance.simulation.setup import TRACKED_PAST_PLAN, _Setup, _State

#: Reduced robots whose smallest N[S, S] pivot falls below this are flagged near-intolerable; the
#: pivots are damped there (``linalg.PIVOT_EPS``), so JVJA's rates and λ stay finite.
NEAR_INTOLERABLE = PIVOT_EPS


def _step(s: _Setup, state: _State, k: int, rec: dict, x_des, xd_des) -> None:
    """One sample the reference way: rates at ``q``, indices, record, then ``q ← q + q̇ dt``."""
    arm, q = s.arm, state.q
    J = arm.jacobian(q)
    x, err = arm.fk_and_error(x_des, q)
    xd_cmd = xd_des + s.feedback_gain * err
    proj = projection(J)
    flag = FLAG_NEAR_SINGULAR if proj.sigma_min < SIGMA_EPS else 0
    planned = None
    box = arm_rate_box(arm, q, s.horizon) if s.limits else None
    if s.reference is not None and (not state.locked or state.lock_jump is None):
        planned = _tracking_rates(s, s.reference, k, q, J, xd_cmd, proj)
        if box is not None:  # the plan's rates, nearest inside the box (L4 with that target)
            sol = bounded_least_norm(J, xd_cmd, box[0], box[1], target=planned, proj=proj)
            planned = sol.qd
            if not state.locked:
                flag |= _box_flags(sol.active, sol.scale)
    elif not state.locked or state.lock_jump is None:
        opts = dict(s.options or {}, arm=arm, q=q, tolerate=True, proj=proj)
        if box is None:
            planned = resolve(s.algorithm, J, xd_cmd, s.sc, **opts)
        else:
            res = resolve_bounded(s.algorithm, J, xd_cmd, s.sc, bounds=box, **opts)
            planned = res.qd
            if not state.locked:
                flag |= _box_flags(res.active, res.scale)
    if state.locked:
        qd_cmd, lflag = _locked_rates(s, state, J, xd_cmd, planned, box)
        flag = lflag
    else:
        qd_cmd = cast(np.ndarray, planned)  # not locked: a branch above planned the rates
        cap = (s.options or {}).get("max_step")  # a resolver whose null-space step is capped
        if cap is not None and np.linalg.norm(qd_cmd - proj.Jpinv @ xd_cmd) >= 0.999 * cap:
            flag |= FLAG_STEP_LIMITED
    if np.any(np.abs(qd_cmd) > s.vmax):
        flag |= FLAG_OVER_SPEED
    k_s = condition_numbers(reduced_singular_values(J, s.sc))
    if state.locked:
        parts = np.zeros(s.sc.f)  # the failure has happened; no jump is pending
    else:
        parts, near = _jump_parts(s, proj, J, xd_cmd, qd_cmd, box)
        flag |= near
    state.qd = qd_cmd.copy() if k == 0 else s.servo.follow(state.qd, qd_cmd, s.dt)
    if state.locked:
        state.qd[s.lock_col] = 0.0
    if box is not None:
        flag |= _clip_to_limits(s, q, state.qd)
    _record(rec, k, q, state.qd, qd_cmd, x, x_des, err, parts, k_s, proj.sigma_min, flag)
    state.q = q + state.qd * s.dt


def _locked_rates(s: _Setup, state: _State, J, xd_cmd, planned, box=None) -> tuple[np.ndarray, int]:
    """Least-norm rates of the reduced robot and its flags; the jump the lock causes, once.

    Inside the box (L4) with limits.
    """
    qd_cmd = np.zeros(s.arm.n)
    keep = state.keep
    reduced = projection(J[:, keep])
    flag = FLAG_LOCKED | (FLAG_NEAR_SINGULAR if reduced.sigma_min < SIGMA_EPS else 0)
    if box is None:
        qd_cmd[keep] = reduced.Jpinv @ xd_cmd
    else:
        sol = bounded_least_norm(J[:, keep], xd_cmd, box[0][keep], box[1][keep], proj=reduced)
        qd_cmd[keep] = sol.qd
        flag |= _box_flags(sol.active, sol.scale)
    if state.lock_jump is None:  # the jump the lock causes: reduced rates minus planned rates
        state.lock_jump = float(np.sum((qd_cmd - planned) ** 2))
    return qd_cmd, flag


def _jump_parts(s: _Setup, proj, J, xd_cmd, qd_cmd, box=None) -> tuple[np.ndarray, int]:
    """The jump the planned rates would suffer if a scenario happened now, eq. (9)/(10).

    With limits, against what each reduced robot does inside the box (L4)-(L5).
    """
    sc = s.sc
    flag = FLAG_NEAR_INTOLERABLE if sc.pivots(proj.N).min() < NEAR_INTOLERABLE else 0
    if box is None:
        post = post_failure_rates(proj.Jpinv @ xd_cmd, proj.N, sc, qd_cmd, s.response, damp=True)
    else:
        post, scales = post_failure_under_limits(
            J, xd_cmd, qd_cmd, sc, box[0], box[1], s.response, tolerate=True
        )
        if np.any(scales < 1.0 - SCALE_TOL):
            flag |= FLAG_INTOLERABLE_UNDER_LIMITS
    return sc.weights * np.einsum("fn,fn->f", post - qd_cmd, post - qd_cmd), flag


def _box_flags(active: np.ndarray, scale: float) -> int:
    """FLAG_BOUND_ACTIVE / FLAG_TASK_SCALED of a bounded solution."""
    return (FLAG_BOUND_ACTIVE if active.any() else 0) | (
        FLAG_TASK_SCALED if scale < 1.0 - SCALE_TOL else 0
    )


def _clip_to_limits(s: _Setup, q: np.ndarray, qd: np.ndarray) -> int:
    """Keep the executed step inside the limits; FLAG_SERVO_CLIPPED if it had to.

    A servo that lags its (in-box) command may not carry a joint past a position limit or over
    its velocity limit.
    """
    arm = s.arm
    lo = np.where(np.abs(arm.lower) < NO_LIMIT, (arm.lower - q) / s.dt, -np.inf)
    hi = np.where(np.abs(arm.upper) < NO_LIMIT, (arm.upper - q) / s.dt, np.inf)
    v = s.vlimit if s.vlimit is not None else np.inf  # as the compiled sampler reads it
    lo, hi = np.maximum(lo, -v), np.minimum(hi, v)
    clipped = np.clip(qd, lo, hi)
    changed = bool(np.any(np.abs(clipped - qd) > 1e-12))
    qd[...] = clipped
    return FLAG_SERVO_CLIPPED if changed else 0


def _record(rec, k, q, qd, qd_cmd, x, x_des, err, parts, k_s, sigma_min, flag) -> None:
    """Sample ``k`` of the time histories."""
    rec["q"][k] = q
    rec["qd"][k] = qd
    rec["qd_cmd"][k] = qd_cmd
    rec["x"][k] = x
    rec["x_des"][k] = x_des
    rec["error"][k] = np.linalg.norm(err)
    rec["jvj_parts"][k] = parts
    rec["jvj"][k] = parts.sum()
    rec["rcn"][k] = k_s
    rec["K"][k] = k_s @ k_s
    rec["sigma_min"][k] = sigma_min
    rec["flags"][k] = flag


# MATH.md (W3): the plan's reference tracked in the null space; J q̇ = ẋ_cmd whatever the reference.
def _tracking_rates(s: _Setup, reference: np.ndarray, k: int, q, J, xd_cmd, proj) -> np.ndarray:
    """``J⁺ẋ_cmd + N (q_ref[k+1] − q)/dt``; past the reference's end, JVJA's rates."""
    if k + 1 < len(reference):
        return proj.Jpinv @ xd_cmd + proj.N @ ((reference[k + 1] - q) / s.dt)
    return resolve(TRACKED_PAST_PLAN, J, xd_cmd, s.sc, tolerate=True, proj=proj)
