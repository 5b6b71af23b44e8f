"""The Controller's inertia-weighted JVJA step (docs/MATH.md (D3)): the NumPy reference route.

No compiled kernel yet: the step is the Jacobian, ``M(q)`` by CRBA
(:class:`~fault_tolerance.model.dynamics.ArmDynamics`) and
:func:`~fault_tolerance.resolution.inertia_jvja.jvja_inertia`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.dynamics import ArmDynamics
from fault_tolerance.resolution.inertia_jvja import jvja_inertia


def inertia_step(ctrl) -> Callable:
    """``step(q, xdot, out=None)``: the minimum kinetic-energy-jump rates at ``q``.

    With the controller's limits on, inside the rate box (the bounded reference route of
    :mod:`fault_tolerance.control.bounded_step`, which solves (D3) under the box).
    """
    ctrl._dynamics = ArmDynamics(ctrl.arm)

    def step(q: np.ndarray, xdot: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        q, xdot = np.asarray(q, dtype=float), np.asarray(xdot, dtype=float)
        if (
            q.shape != (ctrl.n,)
            or xdot.shape != (ctrl.m,)
            or not (np.all(np.isfinite(q)) and np.all(np.isfinite(xdot)))
        ):
            raise InvalidInput(
                f"q must be ({ctrl.n},) and xdot ({ctrl.m},), finite; got {q.shape}, {xdot.shape}"
            )
        J = ctrl.jacobian(q)
        M = ctrl._dynamics.mass_matrix(q)
        qd = jvja_inertia(J, np.asarray(xdot, dtype=float), ctrl.scenarios, M=M,
                          tolerate=ctrl.tolerate)  # fmt: skip
        if out is None:
            return qd
        out[...] = qd
        return out

    step.__name__ = "jvja_inertia"
    if not ctrl.limits:
        return step
    from fault_tolerance.control.bounded_step import bounded_step

    return bounded_step(ctrl, "jvja_inertia", step, ctrl.horizon)
