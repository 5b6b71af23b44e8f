"""One arm: a Pinocchio model reduced to its active joints, a tip frame and a task.

The task coordinates are rows of the tip frame's placement and the task Jacobian the same rows of
Pinocchio's frame Jacobian in ``LOCAL_WORLD_ALIGNED`` (linear velocity of the frame origin and
angular velocity, both in world axes), ordered ``x y z rx ry rz``. No kinematics is written by
hand: forward kinematics and Jacobians come from Pinocchio.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import InvalidInput, InvalidTask, JointNotFound, URDFError
from fault_tolerance.model.chains import frame_id, joint_kind

if TYPE_CHECKING:
    from fault_tolerance.model.formats.urdf import URDFDescription

TASK_ROWS = ("x", "y", "z", "rx", "ry", "rz")
TASKS = {
    "planar": ("x", "y"),
    "position": ("x", "y", "z"),
    "pose": TASK_ROWS,
}


def parse_task(task: str | Sequence[str]) -> tuple[str, ...]:
    """Task rows from ``"planar"``, ``"position"``, ``"pose"`` or a list of row names.

    Rows are returned in the canonical order ``x y z rx ry rz``; a comma-separated string
    (``"x,y,rz"``) is accepted too.
    """
    if isinstance(task, str):
        if task in TASKS:
            return TASKS[task]
        names = [t.strip() for t in task.split(",") if t.strip()]
    else:
        names = [str(t) for t in task]
    bad = [t for t in names if t not in TASK_ROWS]
    if not names or bad:
        raise InvalidTask(
            f"task {task!r} is not allowed; use one of {sorted(TASKS)} or a list of rows among "
            f"{list(TASK_ROWS)}"
        )
    if len(set(names)) != len(names):
        raise InvalidTask(f"task {task!r} repeats a row; rows must be distinct")
    return tuple(r for r in TASK_ROWS if r in names)


#: Most active joints an arm may have. Measured (scripts/urdf_scaling.py): Pinocchio's
#: ``model.createData()`` for a serial chain of N joints takes about 75·N³ bytes and grows as N³ in
#: time (N = 200: 0.6 GB, 1.8 s; N = 300: 1.8 GB, 5.7 s; N = 1000 would need ~60 GB).
MAX_ACTIVE_JOINTS = 200


class Arm:
    """A Pinocchio model of the active joints, one tip frame and one task.

    Build it with :func:`load_arm`. The model holds only the active joints (the others are fixed
    with ``pin.buildReducedModel``), so ``q`` has one entry per active joint, in the column order
    of :meth:`jacobian`.
    """

    def __init__(
        self,
        model: pin.Model,
        tip: str,
        task: str | Sequence[str] = "position",
        *,
        name: str = "",
        visual_model: pin.GeometryModel | None = None,
        default_lockable: Sequence[str] | None = None,
        source: str = "",
        package_dirs: Sequence[str] = (),
        q_reference: np.ndarray | None = None,
    ) -> None:
        label = source or name or model.name or "model"
        odd = [j for j in range(1, model.njoints) if model.joints[j].nq != model.joints[j].nv]
        if odd:
            kinds = [f"'{model.names[j]}' ({joint_kind(model.joints[j])})" for j in odd]
            raise URDFError(
                f"{label}: active joint(s) {', '.join(kinds)} are not supported; an arm moves "
                "revolute and prismatic joints (continuous ones when loaded from a URDF file); "
                "leave these out of the active joints (joints=[...], --joints) to hold them fixed"
            )
        if model.nv == 0:
            raise URDFError(
                f"{label}: the model has no moving joint; an arm needs at least one "
                "revolute or prismatic joint"
            )
        if model.nv > MAX_ACTIVE_JOINTS:
            raise URDFError(
                f"{label}: {model.nv} active joints; at most {MAX_ACTIVE_JOINTS} are accepted "
                "(Pinocchio's data for N joints takes about 75·N³ bytes: 0.6 GB at 200, 60 GB at "
                "1000); choose fewer with --joints or a tip nearer the base with --tip"
            )
        frame_id_ = frame_id(model, tip)
        self.model = model
        self.data = model.createData()
        self.name = name or model.name
        self.tip = tip
        self.frame_id = frame_id_
        self.task = parse_task(task)
        self.rows = np.array([TASK_ROWS.index(r) for r in self.task], dtype=int)
        self.visual_model = visual_model
        self.source = source
        self.package_dirs = [str(d) for d in package_dirs]
        self.xacro_args: dict[str, str] = {}  # set by load_arm for xacro sources
        self.description: URDFDescription | None = (
            None  # the checked URDFDescription, when loaded from a file
        )
        self.description_format: str | None = None  # its format's name (formats/registry.py)
        self.joint_names: list[str] = [
            model.names[j] for j in range(1, model.njoints) if model.joints[j].nv > 0
        ]
        self.default_lockable = (
            list(default_lockable) if default_lockable else list(self.joint_names)
        )
        self.q_reference = (
            self.neutral() if q_reference is None else np.asarray(q_reference, dtype=float).copy()
        )

    # -- sizes and limits -------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of active joints (columns of J)."""
        return self.model.nv

    @property
    def m(self) -> int:
        """Number of task rows."""
        return len(self.rows)

    @property
    def redundancy(self) -> int:
        """Degree of redundancy ``r = n - m``."""
        return self.n - self.m

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits [rad or m], shape (n,)."""
        return np.asarray(self.model.lowerPositionLimit, dtype=float).copy()

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits [rad or m], shape (n,)."""
        return np.asarray(self.model.upperPositionLimit, dtype=float).copy()

    @property
    def velocity_limit(self) -> np.ndarray:
        """Velocity limits [rad/s or m/s], shape (n,)."""
        return np.asarray(self.model.velocityLimit, dtype=float).copy()

    def rate_bounds(
        self, q: np.ndarray, horizon: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rate box ``(qd_lo, qd_hi)`` at ``q`` from the position and velocity limits (L1).

        A joint covers at most its distance to a limit within ``horizon`` [s] (default
        :data:`~fault_tolerance.model.joint_limits.RATE_HORIZON`, 0.05 s; use at least the time step) and never exceeds its
        velocity limit (defaults where the URDF has none: :func:`~fault_tolerance.model.joint_limits.velocity_limits`);
        continuous joints have no position limit. See :mod:`fault_tolerance.resolution.bounded`.

        Example:
            >>> from fault_tolerance import load_arm
            >>> arm = load_arm("planar_3r")
            >>> lo, hi = arm.rate_bounds([3.1, 0.0, 0.0])
            >>> round(float(hi[0]), 4), float(hi[1])
            (0.8318, 3.0)
        """
        from fault_tolerance.model.joint_limits import RATE_HORIZON, arm_rate_box

        return arm_rate_box(self, q, RATE_HORIZON if horizon is None else horizon)

    def neutral(self) -> np.ndarray:
        """Pinocchio's neutral configuration, shape (n,)."""
        return np.asarray(pin.neutral(self.model), dtype=float).copy()

    def random_q(self, rng: np.random.Generator) -> np.ndarray:
        """A configuration drawn uniformly within the limits (±π where a limit is infinite)."""
        lo = np.where(np.isfinite(self.lower), self.lower, -np.pi)
        hi = np.where(np.isfinite(self.upper), self.upper, np.pi)
        return rng.uniform(lo, hi)

    def joint_index(self, joint: str | int) -> int:
        """Column index of an active joint given by name or index."""
        if isinstance(joint, (int, np.integer)) and not isinstance(joint, bool):
            if 0 <= int(joint) < self.n:
                return int(joint)
            raise JointNotFound(str(joint), self.joint_names)
        if joint in self.joint_names:
            return self.joint_names.index(joint)
        raise JointNotFound(str(joint), self.joint_names)

    def check_q(self, q: np.ndarray | Sequence[float], name: str = "q") -> np.ndarray:
        """``q`` as a float array of shape (n,), or :class:`InvalidInput` naming ``name``."""
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise InvalidInput(f"{name} must be {self.n} numbers, got {q!r}") from None
        if q.shape != (self.n,):
            raise InvalidInput(
                f"{name} has shape {q.shape}; {self.name} needs shape ({self.n},) for joints "
                f"{self.joint_names}"
            )
        if not np.all(np.isfinite(q)):
            raise InvalidInput(f"{name} must be finite, got {q.tolist()}")
        return q

    # -- kinematics (all from Pinocchio) ----------------------------------------------------
    def placement(self, q: np.ndarray) -> pin.SE3:
        """Placement of the tip frame in the world."""
        pin.framesForwardKinematics(self.model, self.data, self.check_q(q))
        return self.data.oMf[self.frame_id].copy()

    def fk(self, q: np.ndarray) -> np.ndarray:
        """Task coordinates of the tip, shape (m,).

        Linear rows are the frame origin [m]; angular rows the rotation vector ``log3(R)`` [rad].
        """
        return self._coords(self.placement(q))

    def fk_and_error(self, x_des: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(fk(q), task_error(x_des, q))`` from one forward-kinematics pass (for loops)."""
        M = self.placement(q)
        return self._coords(M), self._error(x_des, M)

    def _coords(self, M: pin.SE3) -> np.ndarray:
        x6 = np.concatenate([M.translation, pin.log3(M.rotation)])
        return x6[self.rows]

    def task_error(self, x_des: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Task-space error ``x_des − x(q)``, shape (m,), in the velocity coordinates of J.

        Linear rows subtract. With all three angular rows the orientation error is the world-frame
        rotation vector ``log3(R_des R(q)ᵀ)`` (``R_des = exp3`` of the desired rotation vector);
        with only some angular rows their rotation-vector components subtract.
        """
        return self._error(x_des, self.placement(q))

    def _error(self, x_des: np.ndarray, M: pin.SE3) -> np.ndarray:
        x_des = np.asarray(x_des, dtype=float)
        if x_des.shape != (self.m,):
            raise InvalidInput(f"x_des has shape {x_des.shape}; the task needs ({self.m},)")
        full = np.zeros(6)
        full[self.rows] = x_des
        err = np.zeros(6)
        err[:3] = full[:3] - M.translation
        ang = [r for r in self.rows if r >= 3]
        if len(ang) == 3:
            err[3:] = pin.log3(pin.exp3(full[3:]) @ M.rotation.T)
        elif ang:
            err[3:] = full[3:] - pin.log3(M.rotation)
        return err[self.rows]

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Task Jacobian ``J(q)``, shape (m, n), ``LOCAL_WORLD_ALIGNED`` rows ``x y z rx ry rz``."""
        J6 = pin.computeFrameJacobian(
            self.model, self.data, self.check_q(q), self.frame_id, pin.LOCAL_WORLD_ALIGNED
        )
        return J6.reshape(6, self.n)[self.rows]  # one joint: eigenpy gives shape (6,)

    def jacobian_unchecked(self, q: np.ndarray) -> np.ndarray:
        """As :meth:`jacobian` without input validation (for control loops), a view of 6 rows."""
        return pin.computeFrameJacobian(
            self.model, self.data, q, self.frame_id, pin.LOCAL_WORLD_ALIGNED
        ).reshape(6, self.n)[self.rows]

    def jacobian_derivatives(self, q: np.ndarray) -> np.ndarray:
        r"""Partial derivatives of the task Jacobian, ``dJ[j] = ∂J/∂q_j``, shape (n, m, n).

        Pinocchio's kinematic Hessian in closed form: in the WORLD convention the column of joint
        ``k`` moves with every joint ``j`` before it on the chain as the Lie bracket
        :math:`\partial J_k/\partial q_j = J_j \times J_k` (``j < k``; zero otherwise). The
        ``LOCAL_WORLD_ALIGNED`` rows follow from :math:`J_v = J^W_v + J^W_\omega \times p`.
        Checked against central differences of :meth:`jacobian` in the tests.
        """
        q = self.check_q(q)
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        p = pin.updateFramePlacement(model, data, self.frame_id).translation.copy()
        Jw = pin.getFrameJacobian(model, data, self.frame_id, pin.WORLD).reshape(6, self.n)
        Jl = pin.getFrameJacobian(model, data, self.frame_id, pin.LOCAL_WORLD_ALIGNED).reshape(
            6, self.n
        )
        n = self.n
        vw, ww = Jw[:3], Jw[3:]
        dJw = np.zeros((n, 6, n))
        for j in range(n):
            k = np.arange(j + 1, n)
            # spatial cross product [v1; w1] x [v2; w2] = [w1 x v2 + v1 x w2; w1 x w2]
            dJw[j, :3, k] = np.cross(ww[:, j], vw[:, k].T) + np.cross(vw[:, j], ww[:, k].T)
            dJw[j, 3:, k] = np.cross(ww[:, j], ww[:, k].T)
        dJ = dJw.copy()
        for j in range(n):
            dp = Jl[:3, j]
            dJ[j, :3, :] += np.cross(dJw[j, 3:, :].T, p).T + np.cross(ww.T, dp).T
        return dJ[:, self.rows, :]

    # -- description ------------------------------------------------------------------------
    @cached_property
    def frame_names(self) -> list[str]:
        """All frame names of the model (candidate tip frames)."""
        return [f.name for f in self.model.frames]

    def __repr__(self) -> str:
        return (
            f"Arm({self.name!r}, tip={self.tip!r}, task={'/'.join(self.task)}, n={self.n}, "
            f"m={self.m}, r={self.redundancy})"
        )


#: Names that lived in this module before the split into catalog / chains / loading;
#: kept importable from here for code written against the old layout.
