"""Benchmark rows of the bounded step when the task is out of reach in the rate box (``s < 1``).

* ``jvja_bounded_scaled``, ``lnva_bounded_scaled``: ``Controller(limits=True)`` JVJA and LNVA
  steps on configurations of the pool with ``ẋ`` grown until the task is scaled (L3) and most
  joints are held at a bound (the long chains' cost). Their
  targets compare them to the unbounded steps of the same arm, timed again in this group's rounds
  (``jvja_unbounded_scaled``, ``lnva_unbounded_scaled``, on the arm's pool), so that a change of the
  machine's speed between groups does not enter the ratio;
* ``pink_tick``: one QP tick of pink (PyPI ``pin-pink``, solver daqp) on the same configurations:
  a frame task whose target is the pose moved by ``ẋ h``, pink's default limits (position and
  velocity) at ``dt = h``; skipped with an ``info: pink not installed`` line when absent;
* ``qp_soft_task``: one direct quadprog call of the same soft-task form,
  ``min ½‖J q̇ − ẋ‖² + ½ε‖q̇‖²`` in the rate box (L1) (``ε = 1e-6``), its Jacobian and box included.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import numpy as np

from fault_tolerance.bench.routes import installed

DESCRIPTIONS = {
    "jvja_bounded_scaled": "JVJA step with joint limits on, task scaled (s < 1, most joints at a "
    "bound)",
    "lnva_bounded_scaled": "LNVA step with joint limits on, task scaled (s < 1, most joints at a "
    "bound)",
    "pink_tick": "one pink QP tick (daqp) of a frame task moved by ẋ h, pink's limits",
    "qp_soft_task": "one quadprog call: min ½‖J q̇ − ẋ‖² + ½ε‖q̇‖² in the rate box",
    "jvja_unbounded_scaled": "the unbounded JVJA step, timed in the rounds of the task-scaled rows",
    "lnva_unbounded_scaled": "the unbounded LNVA step, timed in the rounds of the task-scaled rows",
}
#: Regularisation of the soft-task QP (quadprog needs a positive definite Hessian).
SOFT_EPS = 1e-6

#: Configurations of the pool used (the scaled bounded step of a long chain takes milliseconds).
POOL = 4
#: Growth of ``ẋ`` tried until the task is scaled with at least half of the joints at a bound.
GAINS = (1.0, 3.0, 10.0, 30.0, 100.0)


def _scaled_pool(case, ctrl) -> list[tuple]:
    """``(q, ẋ, out)`` where the bounded LNVA step scales the task with half the joints held."""
    pool = []
    for q, xd in case.qx:
        for gain in GAINS:
            ctrl.lnva(q, xd * gain)
            if ctrl.last_scale < 1.0 and 2 * int(ctrl.last_active.sum()) >= case.arm.n:
                pool.append((q, xd * gain, case.out))
                break
        if len(pool) == POOL:
            break
    return pool


def scaled_rows(case) -> dict[str, tuple[Callable[..., np.ndarray], list[tuple]]]:
    """The rows above (none when no configuration of the pool scales the task)."""
    from fault_tolerance.control.controller import Controller

    ctrl = Controller(case.arm, case.spec["lockable"], backend=case.ctrl.backend)
    pool = _scaled_pool(case, ctrl)
    if not pool:
        return {}
    rows = {"jvja_bounded_scaled": (ctrl.jvja, pool), "lnva_bounded_scaled": (ctrl.lnva, pool),
            "jvja_unbounded_scaled": (case.ctrl.jvja, case.qxo),
            "lnva_unbounded_scaled": (case.ctrl.lnva, case.qxo)}  # fmt: skip
    args = [(q, xd) for q, xd, _ in pool]
    if installed("quadprog"):
        rows["qp_soft_task"] = (_soft_task_qp(case.arm, ctrl), args)
    if installed("pink"):
        rows["pink_tick"] = _pink_row(case.arm, ctrl.horizon, args)
    else:
        print("info: pink not installed (pip install 'fault_tolerance[bench]'): no pink_tick row",
              file=sys.stderr)  # fmt: skip
    return rows


def _soft_task_qp(arm, ctrl) -> Callable[..., np.ndarray]:
    """``qp(q, ẋ)``: the soft-task QP of ``q`` in its rate box, one quadprog call."""
    import quadprog

    n, h = arm.n, ctrl.horizon
    eye = np.eye(n)
    C = np.hstack([eye, -eye])

    def qp(q, xd):
        J = ctrl.jacobian(q)
        lo, hi = arm.rate_bounds(q, h)
        H = J.T @ J + SOFT_EPS * eye
        return quadprog.solve_qp(H, J.T @ xd, C, np.concatenate([lo, -hi]), 0)[0]

    return qp


def _pink_row(arm, h: float, args: list[tuple]) -> tuple[Callable[..., np.ndarray], list[tuple]]:
    """Pink's tick ``(configuration update, solve_ik)`` and its arguments ``(q, task)``."""
    import pink
    import pinocchio as pin
    from pink.tasks import FrameTask

    model = arm.model
    cfg = pink.Configuration(model, model.createData(), args[0][0])
    name = model.frames[arm.frame_id].name
    calls = []
    for q, xd in args:
        cfg.update(q)
        task = FrameTask(name, position_cost=1.0, orientation_cost=1.0)
        twist = np.zeros(6)
        twist[arm.rows] = xd  # the task's rows of the LOCAL_WORLD_ALIGNED twist
        pose = cfg.get_transform_frame_to_world(name)
        task.set_target(pin.SE3(pin.exp3(twist[3:] * h) @ pose.rotation,
                                pose.translation + twist[:3] * h))  # fmt: skip
        calls.append((q, [task]))

    def tick(q, tasks):
        cfg.update(q)
        return pink.solve_ik(cfg, tasks, h, solver="daqp")

    return tick, calls


__all__ = ["DESCRIPTIONS", "scaled_rows"]
