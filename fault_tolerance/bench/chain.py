"""A synthetic serial chain of n revolute joints for the benchmark's scaling table (n = 7 ... 50).

Joints alternate between z, y and x axes, links of length ``1/n`` m along z (reach 1 m), limits
``±π``, velocity limit 2 rad/s; the tip frame ``tip`` sits one link past the last joint. Built
with Pinocchio's API (no URDF file).

Example:
    >>> from fault_tolerance.bench.chain import synthetic_chain
    >>> arm = synthetic_chain(10)
    >>> (arm.n, arm.m)
    (10, 6)
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from fault_tolerance.model.arm import Arm

_AXES = (pin.JointModelRZ, pin.JointModelRY, pin.JointModelRX)


def synthetic_chain(n: int, task: str = "pose") -> Arm:
    """The ``n``-joint chain as an :class:`~fault_tolerance.model.arm.Arm` (task ``pose`` by default)."""
    model = pin.Model()
    model.name = f"chain_{n}"
    link = 1.0 / n
    parent = 0
    for i in range(n):
        offset = pin.SE3(np.eye(3), np.array([0.0, 0.0, link if i else 0.0]))
        parent = model.addJoint(parent, _AXES[i % 3](), offset, f"joint{i + 1}")
        model.appendBodyToJoint(
            parent, pin.Inertia.FromCylinder(0.1, 0.02, link), pin.SE3.Identity()
        )
    model.lowerPositionLimit = -np.pi * np.ones(n)
    model.upperPositionLimit = np.pi * np.ones(n)
    model.velocityLimit = 2.0 * np.ones(n)
    tip = pin.SE3(np.eye(3), np.array([0.0, 0.0, link]))
    model.addFrame(pin.Frame("tip", parent, tip, pin.FrameType.OP_FRAME))
    q_ref = np.tile([0.0, 0.4, 0.3], n)[:n]
    return Arm(model, "tip", task, name=f"chain_{n}", source=f"chain_{n}", q_reference=q_ref)
