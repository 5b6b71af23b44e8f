"""``load_arm``: an :class:`~.arm.Arm` from a catalog name, an example-robot-data name or a file."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fault_tolerance.errors import InvalidInput, RobotNotFound
from fault_tolerance.model.arm import Arm
from fault_tolerance.model.arm_record import remember, remember_example
from fault_tolerance.model.catalog import (
    EXAMPLE_ROBOTS,
    catalog,
    example_robot_names,
    preset_names,
    robot_path,
)
from fault_tolerance.model.chains import active_q, reduce_model
from fault_tolerance.model.formats.packages import forget_package_search
from fault_tolerance.model.formats.registry import (
    DescriptionFormat,
    is_description_path,
    read_description,
)


def load_arm(
    robot: str | Path,
    *,
    tip: str | None = None,
    task: str | Sequence[str] | None = None,
    joints: Sequence[str] | None = None,
    package_dirs: Sequence[str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
) -> Arm:
    """Load an arm by catalog name, example-robot-data name, or a URDF, xacro or MJCF path.

    Args:
        robot: ``"planar_3r"``, ``"spatial_4r"``, ``"powercube_3r"``, ``"iiwa"``, an
            example-robot-data name (``"panda"``, ``"ur5"``, ``"xarm7"``, ...) or the path of a
            URDF file, a xacro file (``.xacro``, ``.urdf.xacro``; expanded without ROS) or a MuJoCo
            MJCF file (``.xml`` whose root is ``<mujoco>``); the format is recognised by
            :func:`~.formats.registry.format_of`.
        tip: Tip frame (default: the catalog's; for a URDF file its only leaf link, else an
            error listing the leaf links; for an MJCF file the end of the serial chain from the
            root body or a site on it (bodies and sites are frames); for example-robot-data the
            preset or last frame).
        task: ``"planar"``, ``"position"``, ``"pose"`` or a list of rows among ``x y z rx ry rz``.
        joints: Active joint names; the others are fixed (default: the chain to the tip).
        package_dirs: Folders of the ROS packages that ``package://pkg/...`` and
            ``$(find pkg)`` name: ``DIR/pkg``, or a ``DIR`` whose ``package.xml`` names ``pkg``.
        xacro_args: Arguments of a xacro file, ``{"name": "value"}`` (``--xacro-arg name:=value``).

    Example:
        >>> arm = load_arm("planar_3r")
        >>> arm.joint_names
        ['joint1', 'joint2', 'joint3']
    """
    forget_package_search()  # packages added or moved since the last load are seen
    name = str(robot)
    shipped = catalog()
    path = Path(name).expanduser()
    if name not in shipped and (is_description_path(path) or path.exists()):
        fmt, desc = read_description(path, package_dirs, xacro_args)
        return arm_from_description(fmt, desc, tip, task, joints, package_dirs, xacro_args)
    if xacro_args:
        raise InvalidInput(
            f"xacro_args {sorted(xacro_args)} given for '{name}', which is not a xacro file"
        )
    if name in shipped:
        return _load_shipped(name, shipped[name], tip, task, joints, package_dirs)
    return _load_example_robot(name, tip, task, joints, shipped)


def _load_shipped(name: str, entry: dict, tip, task, joints, package_dirs) -> Arm:
    """A robot of ``robots/catalog.json``."""
    path = robot_path(entry["urdf"])
    fmt, desc = read_description(path, package_dirs)
    model = fmt.build_model(desc)
    visual = fmt.build_visuals(model, desc, package_dirs)
    tip = entry["tip"] if tip is None else tip
    # optional reference posture of the full model (catalog "q_reference"): joints left out
    # of ``joints`` are fixed there, the active ones give Arm.q_reference
    q_full = entry.get("q_reference")
    q_full = None if q_full is None else np.asarray(q_full, dtype=float)
    full = model
    model, visual = reduce_model(model, tip, joints, q_full, visual_model=visual)
    arm = Arm(
        model,
        tip,
        entry["task"] if task is None else task,
        name=name,
        visual_model=visual,
        default_lockable=entry.get("lockable"),
        source=name,
        q_reference=None if q_full is None else active_q(full, model, q_full),
    )
    return remember(arm, "shipped", desc.data, q_full, fmt=fmt.records_as)


def arm_from_description(
    fmt: DescriptionFormat,
    desc,
    tip: str | None = None,
    task=None,
    joints: Sequence[str] | None = None,
    package_dirs: Sequence[str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
) -> Arm:
    """An arm from a checked description of format ``fmt`` (:func:`~.registry.read_description`)."""
    path = desc.path
    model = fmt.build_model(desc)
    visual = fmt.build_visuals(model, desc, package_dirs)
    tip = fmt.default_tip(desc) if tip is None else tip
    model, visual = reduce_model(model, tip, joints, visual_model=visual, label=str(path))
    mimics = [j for j in model.names[1:] if j in desc.mimic]
    if mimics:
        raise fmt.error(
            f"{path}: active joint(s) {mimics} follow other joints ({fmt.coupling}); Pinocchio "
            "would move them independently. Leave them out of the active joints (joints=[...], "
            "--joints) to hold them fixed, or choose a tip frame that does not depend on them"
        )
    arm = Arm(
        model,
        tip,
        "position" if task is None else task,
        name=_stem(path.name),
        visual_model=visual,
        source=str(Path(path).resolve()),
        package_dirs=package_dirs or (),
    )
    arm.xacro_args = dict(xacro_args or {})
    arm.description = desc
    arm.description_format = fmt.name
    return remember(arm, "file", desc.data, fmt=fmt.records_as)


def _stem(name: str) -> str:
    """``ur5e.urdf.xacro`` -> ``ur5e``."""
    for suffix in (".xacro", ".urdf", ".xml"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name


def _load_example_robot(name: str, tip: str | None, task, joints, shipped: dict) -> Arm:
    """An arm of example-robot-data, with our preset tip, task and joints where we have one."""
    known = list(shipped) + example_robot_names()
    if name not in example_robot_names():
        raise RobotNotFound(name, known, suits=preset_names())
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
    q_active = None if q_ref is None else active_q(robot.model, model, q_ref)
    task = preset.get("task", "position") if task is None else task
    arm = Arm(model, tip, task, name=name, visual_model=visual, source=name, q_reference=q_active)
    return remember_example(arm, name, robot.model, q_ref)


def arm_from_meta(meta: dict) -> Arm:
    """Rebuild the arm a saved run was made with (its ``meta``: source, tip, task, joints)."""
    return load_arm(
        meta.get("source") or meta["robot"],
        tip=meta.get("tip"),
        task=meta.get("task"),
        joints=meta.get("joint_names"),
        package_dirs=meta.get("package_dirs") or None,
        xacro_args=meta.get("xacro_args") or None,
    )
