"""``inspect``: a readable description of a robot (its tree, chain, task, intolerable joints)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fault_tolerance.errors import RobotNotFound
from fault_tolerance.model.catalog import catalog, example_robot_names, preset_names, robot_path
from fault_tolerance.model.chains import serial_chains
from fault_tolerance.model.formats.registry import is_description_path, read_description
from fault_tolerance.model.loading import arm_from_description, load_arm
from fault_tolerance.numerics.linalg import PIVOT_TOL, projection
from fault_tolerance.planning.start_checks import STRUCTURAL_SAMPLES, intolerable_everywhere
from fault_tolerance.resolution.scenarios import scenarios


def urdf_path_of(target: str) -> Path:
    """The description file behind a catalog name, an example-robot-data name or a path."""
    if target in catalog():
        return robot_path(catalog()[target]["urdf"])
    if target in example_robot_names():
        from example_robot_data.robots_loader import ROBOTS, getModelPath

        loader = ROBOTS[target]
        sub = Path(loader.path) / loader.urdf_subpath / loader.urdf_filename
        return Path(getModelPath(str(sub))) / sub
    path = Path(target).expanduser()
    if not path.exists() and not is_description_path(path):
        raise RobotNotFound(target, list(catalog()) + example_robot_names(), suits=preset_names())
    return path


def inspect_text(
    target: str,
    *,
    tip: str | None = None,
    task=None,
    joints=None,
    package_dirs=None,
    xacro_args=None,
) -> str:
    """A readable description of a robot: tree, serial chains, chain, task, intolerable joints.

    ``target`` is a robot name or a description file (URDF, xacro, MJCF); the tree is listed by
    the description's format from the checked (expanded) text.
    """
    path, fmt, desc, arm = _read_target(target, tip, task, joints, package_dirs, xacro_args)
    model = fmt.build_model(desc)
    lines = [f"{target}: {path} ({fmt.label})"] + fmt.tree_lines(desc, model)
    lines += _chain_lines(model, desc)
    if arm is None:
        lines.append(
            "no tip frame given and there are several leaf links: name one with --tip to "
            "see the chain"
        )
        return "\n".join(lines)
    return "\n".join(lines + _arm_lines(arm))


def _read_target(target, tip, task, joints, package_dirs, xacro_args):
    """``(path, format, description, arm)``; the arm is None when a tip must be chosen."""
    path = urdf_path_of(target)
    if target in catalog() or target in example_robot_names():
        fmt, desc = read_description(path)
        arm = load_arm(target, tip=tip, task=task, joints=joints, package_dirs=package_dirs)
        return path, fmt, desc, arm
    fmt, desc = read_description(path, package_dirs, xacro_args)
    choose_tip = tip is None and _tip_is_open(fmt, desc)
    # Pinocchio's checks first (their messages are the clearer), then the tree
    arm = (
        None
        if choose_tip
        else arm_from_description(fmt, desc, tip, task, joints, package_dirs, xacro_args)
    )
    return path, fmt, desc, arm


def _tip_is_open(fmt, desc) -> bool:
    """True when the format chooses no default tip for the description (several candidates)."""
    try:
        fmt.default_tip(desc)
    except fmt.error:
        return True
    return False


def _arm_lines(arm) -> list[str]:
    """The chain, the task, σ_min(J) at the reference configuration, the intolerable joints."""
    lines = [
        "",
        f"chain to tip '{arm.tip}': {' -> '.join(arm.joint_names)}",
        f"task {'/'.join(arm.task)}: n = {arm.n}, m = {arm.m}, redundancy r = {arm.redundancy}",
    ]
    q = arm.q_reference
    proj = projection(arm.jacobian(q))
    label = "reference" if np.any(q != arm.neutral()) else "neutral"
    lines.append(
        f"at the {label} configuration {np.round(q, 4).tolist()}: "
        f"σ_min(J) = {proj.sigma_min:.3g}" + ("  (singular)" if proj.sigma_min < 1e-6 else "")
    )
    if arm.redundancy < 1:
        return lines + ["not redundant for this task: any locked joint loses it"]
    sc = scenarios("all", arm.n, r=arm.redundancy, joint_names=arm.joint_names)
    bad = [arm.joint_names[i] for i in sc.columns if proj.N[i, i] < PIVOT_TOL]
    note = "  (J is singular there, so this says little)" if proj.sigma_min < 1e-6 else ""
    lines.append(
        "intolerable joints there (locking one loses the task): "
        + (", ".join(bad) if bad else "none")
        + note
    )
    from fault_tolerance.resolution.limits import inspect_lines

    lines += inspect_lines(arm, q, sc.columns)
    always = [name for (name,) in intolerable_everywhere(arm, sc)]
    lines.append(
        f"intolerable at all of {STRUCTURAL_SAMPLES} random regular configurations "
        "(structurally; leave them out of the lockable set): "
        + (", ".join(always) if always else "none")
    )
    return lines


#: Most serial chains ``inspect`` lists.
MAX_CHAINS_SHOWN = 12


def _chain_lines(model, desc) -> list[str]:
    """The serial chains of the tree, each with the ``--tip``/``--joints`` that selects it."""
    chains = serial_chains(model, desc.leaves, tuple(desc.mimic), min_joints=2)
    if not chains:
        return []
    lines = [
        "",
        "serial chains (leaf links grouped by their moving joints; mimic joints left out):",
    ]
    for c in chains[:MAX_CHAINS_SHOWN]:
        others = [e for e in c.ends if e != c.tip]
        more = ""
        if others:
            shown = ", ".join(others[:3]) + (f" +{len(others) - 3}" if len(others) > 3 else "")
            more = f"; also ends at {shown}"
        lines.append(f"  {len(c.joints)} joints{more}:")
        lines.append(f"    {c.option()}")
    if len(chains) > MAX_CHAINS_SHOWN:
        lines.append(f"  ... and {len(chains) - MAX_CHAINS_SHOWN} shorter chains")
    return lines
