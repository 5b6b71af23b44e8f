"""One arm: a Pinocchio model reduced to its active joints, a tip frame and a task.

The task coordinates are rows of the tip frame's placement and the task Jacobian the same rows of
Pinocchio's frame Jacobian in ``LOCAL_WORLD_ALIGNED`` (linear velocity of the frame origin and
angular velocity, both in world axes), ordered ``x y z rx ry rz``. No kinematics is written by
hand: forward kinematics and Jacobians come from Pinocchio.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from .errors import (
    AmbiguousFrame,
    FrameNotFound,
    InvalidInput,
    InvalidTask,
    JointNotFound,
    RobotNotFound,
    URDFError,
)

TASK_ROWS = ("x", "y", "z", "rx", "ry", "rz")
TASKS = {
    "planar": ("x", "y"),
    "position": ("x", "y", "z"),
    "pose": TASK_ROWS,
}

#: Arms of example-robot-data with the defaults we give them: tip frame, task, active joints.
EXAMPLE_ROBOTS: dict[str, dict] = {
    "panda": {
        "tip": "panda_hand_tcp",
        "task": "pose",
        "joints": [f"panda_joint{i}" for i in range(1, 8)],
        "description": "Franka Panda (example-robot-data), fingers fixed",
    },
    "ur5": {
        "tip": "tool0",
        "task": "position",
        "joints": None,
        "description": "Universal Robots UR5 (example-robot-data)",
    },
    "xarm7": {
        "tip": "link_eef",
        "task": "pose",
        "joints": None,
        "description": "UFactory xArm7 (example-robot-data)",
    },
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


def catalog() -> dict[str, dict]:
    """The shipped robots (``robots/catalog.json``): URDF file, tip, task, lockable joints."""
    text = resources.files("fault_tolerance.robots").joinpath("catalog.json").read_text()
    return json.loads(text)


def robot_path(filename: str) -> Path:
    """Path of a file shipped in ``robots/`` (works from a checkout and from a wheel)."""
    return Path(str(resources.files("fault_tolerance.robots").joinpath(filename)))


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
            kinds = [f"'{model.names[j]}' ({_joint_kind(model.joints[j])})" for j in odd]
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
        frame_id = _frame_id(model, tip)
        self.model = model
        self.data = model.createData()
        self.name = name or model.name
        self.tip = tip
        self.frame_id = frame_id
        self.task = parse_task(task)
        self.rows = np.array([TASK_ROWS.index(r) for r in self.task], dtype=int)
        self.visual_model = visual_model
        self.source = source
        self.package_dirs = [str(d) for d in package_dirs]
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

    def check_q(self, q: np.ndarray | Sequence[float]) -> np.ndarray:
        """``q`` as a float array of shape (n,), or :class:`InvalidInput` saying what is wrong."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,):
            raise InvalidInput(
                f"q has shape {q.shape}; {self.name} needs shape ({self.n},) for joints "
                f"{self.joint_names}"
            )
        if not np.all(np.isfinite(q)):
            raise InvalidInput(f"q must be finite, got {q.tolist()}")
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

    def resolve(
        self, algorithm: str, q: np.ndarray, xdot: np.ndarray, lockable=None, **options
    ) -> np.ndarray:
        """Joint rates of ``algorithm`` at ``q`` for task velocity ``xdot``; lockable joints by name.

        Shorthand for ``ft.resolve(algorithm, arm.jacobian(q), xdot, lockable, arm=arm, q=q)``;
        ``lockable`` defaults to the arm's default lockable joints.

        Example:
            >>> arm = load_arm("planar_3r")
            >>> qd = arm.resolve("jvja", [0.3, 1.2, 1.0], [0.1, 0.0], ["joint2", "joint3"])
            >>> bool(np.allclose(arm.jacobian([0.3, 1.2, 1.0]) @ qd, [0.1, 0.0]))
            True
        """
        from .planner import resolve

        q = self.check_q(q)
        lockable = self.default_lockable if lockable is None else lockable
        return resolve(algorithm, self.jacobian(q), xdot, lockable, arm=self, q=q, **options)

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


# -- loading --------------------------------------------------------------------------------


def _supporting_joints(model: pin.Model, frame_id: int) -> list[int]:
    """Ids of the moving joints on the chain from the root to a frame, base outwards."""
    joint = model.frames[frame_id].parentJoint
    return [j for j in model.supports[joint] if j > 0 and model.joints[j].nv > 0]


def _joint_kind(joint) -> str:
    """A readable kind for Pinocchio's joint model names (``JointModelRUBZ`` → continuous)."""
    short = joint.shortname()
    for key, kind in (
        ("RUB", "continuous"),
        ("FreeFlyer", "floating"),
        ("Planar", "planar"),
        ("Spherical", "spherical"),
        ("Mimic", "mimic"),
        ("Composite", "composite"),
    ):
        if key in short:
            return kind
    return short


def _frame_id(model: pin.Model, tip: str) -> int:
    """Id of the frame named ``tip``; refused when several frames of that name are at different places."""
    if not model.existFrame(tip):
        raise FrameNotFound(tip, [f.name for f in model.frames])
    same = [f for f in model.frames if f.name == tip]
    first = same[0]
    if any(
        f.parentJoint != first.parentJoint or not f.placement.isApprox(first.placement)
        for f in same[1:]
    ):
        raise AmbiguousFrame(
            tip, [f"{f.name} ({f.type.name} on joint '{model.names[f.parentJoint]}')" for f in same]
        )
    return model.getFrameId(tip)


def reduce_model(
    model: pin.Model,
    tip: str,
    joints: Sequence[str] | None,
    q_reference: np.ndarray | None = None,
    visual_model: pin.GeometryModel | None = None,
    label: str = "",
) -> tuple[pin.Model, pin.GeometryModel | None]:
    """Keep ``joints`` (default: the chain to ``tip``) and fix every other joint at ``q_reference``.

    ``label`` names the robot in error messages (default: the model's name).
    """
    frame_id = _frame_id(model, tip)
    names = [model.names[j] for j in range(1, model.njoints)]
    if joints is None:
        keep = _supporting_joints(model, frame_id)
        if not keep:
            moving = [model.names[j] for j in range(1, model.njoints) if model.joints[j].nv > 0]
            raise URDFError(
                f"{label or model.name}: no moving joint between the root and frame '{tip}'"
                + (
                    f"; the moving joints are {moving}: choose a tip beyond them"
                    if moving
                    else "; the model has no moving joint at all (every joint is fixed)"
                )
            )
    else:
        keep = []
        for name in joints:
            if name not in names:
                raise JointNotFound(name, names)
            keep.append(model.getJointId(name))
    lock = [j for j in range(1, model.njoints) if j not in keep]
    if not lock:
        return model, visual_model
    q_ref = pin.neutral(model) if q_reference is None else np.asarray(q_reference, dtype=float)
    if visual_model is None:
        return pin.buildReducedModel(model, lock, q_ref), None
    reduced, geoms = pin.buildReducedModel(model, [visual_model], lock, q_ref)
    return reduced, geoms[0]


def _load_urdf(
    path: Path, package_dirs: Sequence[str] | None
) -> tuple[pin.Model, pin.GeometryModel | None]:
    """Model and visual geometry of a URDF file; geometry is dropped with a warning if unreadable."""
    model, visual, _ = _load_urdf_file(path, package_dirs)
    return model, visual


def _load_urdf_file(path: Path, package_dirs: Sequence[str] | None):
    """Model, visual geometry and :class:`~.urdf.URDFDescription` of a URDF file.

    Pinocchio reads the text that passed :func:`~.urdf.read_urdf`, never the file again. Meshes
    that cannot be found (``package://`` without ``package_dirs``) drop the visual geometry with a
    warning: the kinematics does not need it.
    """
    from .urdf import native_reason, native_stderr, read_urdf

    desc = read_urdf(path)
    failure = None
    with native_stderr() as log:
        try:
            model = pin.buildModelFromXML(desc.xml)
        except Exception as err:  # Pinocchio raises ValueError / RuntimeError with C++ messages
            failure = err
    if failure is not None:
        reason = native_reason(log) or str(failure)
        raise URDFError(f"{path}: Pinocchio could not build a model from it: {reason}") from failure
    if desc.unlimited:  # continuous joints without <limit>: no velocity or effort limit
        vel, eff = model.velocityLimit.copy(), model.effortLimit.copy()
        for joint in desc.unlimited:
            idx = model.joints[model.getJointId(joint)].idx_v
            vel[idx] = eff[idx] = np.inf
        model.velocityLimit, model.effortLimit = vel, eff
    dirs = [str(d) for d in (package_dirs or [])] + [str(path.parent)]
    failure = None
    with native_stderr() as log, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Pinocchio's notice about package dirs
        try:
            visual = pin.buildGeomFromUrdfString(
                model, desc.xml, pin.GeometryType.VISUAL, package_dirs=dirs
            )
        except Exception as err:
            failure = err
    if failure is not None:
        warnings.warn(
            f"{path}: visual geometry not loaded ({native_reason(log) or failure}); the arm works "
            "without it, the replay shows no meshes. Pass package_dirs (--package-dir) where "
            "package:// meshes live.",
            stacklevel=3,
        )
        visual = None
    return model, visual, desc


def load_arm(
    robot: str | Path,
    *,
    tip: str | None = None,
    task: str | Sequence[str] | None = None,
    joints: Sequence[str] | None = None,
    package_dirs: Sequence[str] | None = None,
) -> Arm:
    """Load an arm by catalog name, example-robot-data name or URDF path.

    Args:
        robot: ``"planar_3r"``, ``"spatial_4r"``, ``"powercube_3r"``, ``"iiwa"``, an
            example-robot-data name (``"panda"``, ``"ur5"``, ``"xarm7"``, ...) or the path of a
            URDF file.
        tip: Tip frame (default: the catalog's; for a URDF file its only leaf link, else an
            error listing the leaf links; for example-robot-data the preset or last frame).
        task: ``"planar"``, ``"position"``, ``"pose"`` or a list of rows among ``x y z rx ry rz``.
        joints: Active joint names; the others are fixed (default: the chain to the tip).
        package_dirs: Folders where ``package://`` meshes of a URDF file are found.

    Example:
        >>> arm = load_arm("planar_3r")
        >>> arm.joint_names
        ['joint1', 'joint2', 'joint3']
    """
    name = str(robot)
    shipped = catalog()
    if name in shipped:
        entry = shipped[name]
        path = robot_path(entry["urdf"])
        model, visual = _load_urdf(path, package_dirs)
        tip = entry["tip"] if tip is None else tip
        # optional reference posture of the full model (catalog "q_reference"): joints left out
        # of ``joints`` are fixed there, the active ones give Arm.q_reference
        q_full = entry.get("q_reference")
        q_full = None if q_full is None else np.asarray(q_full, dtype=float)
        full = model
        model, visual = reduce_model(model, tip, joints, q_full, visual_model=visual)
        q_ref = (
            None
            if q_full is None
            else np.array(
                [
                    q_full[full.joints[full.getJointId(model.names[j])].idx_q]
                    for j in range(1, model.njoints)
                    if model.joints[j].nv > 0
                ]
            )
        )
        return Arm(
            model,
            tip,
            entry["task"] if task is None else task,
            name=name,
            visual_model=visual,
            default_lockable=entry.get("lockable"),
            source=name,
            q_reference=q_ref,
        )
    path = Path(name).expanduser()
    if path.suffix.lower() in (".urdf", ".xml") or path.exists():
        if not path.is_file():
            raise URDFError(f"{path}: no such URDF file")
        from .urdf import default_tip

        model, visual, desc = _load_urdf_file(path, package_dirs)
        tip = default_tip(desc) if tip is None else tip
        model, visual = reduce_model(model, tip, joints, visual_model=visual, label=str(path))
        mimics = [j for j in model.names[1:] if j in desc.mimic]
        if mimics:
            raise URDFError(
                f"{path}: active joint(s) {mimics} follow other joints (<mimic>); Pinocchio would "
                "move them independently. Leave them out of the active joints (joints=[...], "
                "--joints) to hold them fixed, or choose a tip frame that does not depend on them"
            )
        task = "position" if task is None else task
        return Arm(
            model,
            tip,
            task,
            name=path.stem,
            visual_model=visual,
            source=str(path.resolve()),
            package_dirs=package_dirs or (),
        )
    return _load_example_robot(name, tip, task, joints, shipped)


def example_robot_names() -> list[str]:
    """Names example-robot-data can load (empty if its loaders are missing)."""
    try:
        from example_robot_data.robots_loader import ROBOTS
    except ImportError:
        return []
    return sorted(ROBOTS)


def _load_example_robot(name: str, tip: str | None, task, joints, shipped: dict) -> Arm:
    known = list(shipped) + example_robot_names()
    if name not in example_robot_names():
        raise RobotNotFound(name, known)
    import example_robot_data

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = example_robot_data.load(name)
    preset = EXAMPLE_ROBOTS.get(name, {})
    if tip is None:
        tip = preset.get("tip") or robot.model.frames[len(robot.model.frames) - 1].name
    joints = joints if joints is not None else preset.get("joints")
    q_ref = getattr(robot, "q0", None)
    model, visual = reduce_model(robot.model, tip, joints, q_ref, robot.visual_model)
    q_active = None
    if q_ref is not None:
        full = robot.model
        q_active = np.array(
            [
                q_ref[full.joints[full.getJointId(model.names[j])].idx_q]
                for j in range(1, model.njoints)
                if model.joints[j].nv > 0
            ]
        )
    task = preset.get("task", "position") if task is None else task
    return Arm(model, tip, task, name=name, visual_model=visual, source=name, q_reference=q_active)


def arm_from_meta(meta: dict) -> Arm:
    """Rebuild the arm a saved run was made with (its ``meta``: source, tip, task, joints)."""
    return load_arm(
        meta.get("source") or meta["robot"],
        tip=meta.get("tip"),
        task=meta.get("task"),
        joints=meta.get("joint_names"),
        package_dirs=meta.get("package_dirs") or None,
    )
