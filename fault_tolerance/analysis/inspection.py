"""``inspect``: a readable description of a robot (its URDF tree, chain, task, intolerable joints)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from fault_tolerance.errors import RobotNotFound, URDFError
from fault_tolerance.model.catalog import catalog, example_robot_names, preset_names, robot_path
from fault_tolerance.model.chains import serial_chains
from fault_tolerance.model.formats.build import build_model, read_description
from fault_tolerance.model.formats.urdf import read_urdf
from fault_tolerance.model.loading import arm_from_description, is_description_path, load_arm
from fault_tolerance.numerics.linalg import PIVOT_TOL, projection
from fault_tolerance.planning.start_checks import STRUCTURAL_SAMPLES, intolerable_everywhere
from fault_tolerance.resolution.scenarios import scenarios


def urdf_path_of(target: str) -> Path:
    """The URDF file behind a catalog name, an example-robot-data name or a path."""
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

    ``target`` is a robot name, a URDF or a xacro file; the tree is read with yourdfpy from the
    checked (expanded) text.
    """
    path, desc, arm = _read_target(target, tip, task, joints, package_dirs, xacro_args)
    urdf = _yourdfpy_tree(path, desc)
    lines = [f"{target}: {path}"] + _tree_lines(urdf, desc) + _chain_lines(desc)
    if arm is None:
        lines.append(
            "no tip frame given and there are several leaf links: name one with --tip to "
            "see the chain"
        )
        return "\n".join(lines)
    return "\n".join(lines + _arm_lines(arm))


def _read_target(target, tip, task, joints, package_dirs, xacro_args):
    """``(path, description, arm)``; the arm is None when a tip must be chosen among leaves."""
    path = urdf_path_of(target)
    if target in catalog() or target in example_robot_names():
        desc = read_urdf(path)
        arm = load_arm(target, tip=tip, task=task, joints=joints, package_dirs=package_dirs)
        return path, desc, arm
    if not path.is_file():
        raise URDFError(f"{path}: no such URDF file")
    desc = read_description(path, package_dirs, xacro_args)
    choose_tip = tip is None and len(desc.leaves) > 1
    # Pinocchio's checks first (their messages are the clearer), then the tree from yourdfpy
    arm = (
        None
        if choose_tip
        else arm_from_description(desc, tip, task, joints, package_dirs, xacro_args)
    )
    return path, desc, arm


def _yourdfpy_tree(path: Path, desc):
    """The tree as yourdfpy reads it, from the checked bytes (never the file itself)."""
    import yourdfpy  # after the checks: a hostile file is refused without this import's cost

    try:
        return yourdfpy.URDF.load(
            io.BytesIO(desc.data),
            load_meshes=False,
            build_scene_graph=False,
            build_collision_scene_graph=False,
        )
    except Exception as err:  # yourdfpy raises many types
        raise URDFError(f"{path}: yourdfpy could not read it: {err}") from err


def _tree_lines(urdf, desc) -> list[str]:
    """The robot's links and joints, continuous and mimic joints, the candidate tips."""
    lines = [
        f"robot '{urdf.robot.name}': {len(urdf.robot.links)} links, "
        f"{len(urdf.robot.joints)} joints",
        "",
        "joints (parent -> child):",
    ]
    for j in urdf.robot.joints:
        lim = ""
        if j.limit is not None and j.type in ("revolute", "prismatic"):
            lim = (
                f"  limits [{j.limit.lower:.4g}, {j.limit.upper:.4g}], velocity {j.limit.velocity}"
            )
        axis = (
            "" if j.type == "fixed" or j.axis is None else f"  axis {np.round(j.axis, 3).tolist()}"
        )
        lines.append(f"  {j.name:28s} {j.type:10s} {j.parent} -> {j.child}{axis}{lim}")
    if desc.continuous:
        lines.append(
            f"continuous joints, read as revolute with limits ±π: {', '.join(desc.continuous)}"
        )
    if desc.mimic:
        lines.append(
            "mimic joints (held fixed; they cannot be active joints): "
            + ", ".join(f"{a} follows {b}" for a, b in desc.mimic.items())
        )
    return lines + ["", f"candidate tip frames (leaf links): {', '.join(desc.leaves)}"]


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


def _chain_lines(desc) -> list[str]:
    """The serial chains of the tree, each with the ``--tip``/``--joints`` that selects it."""
    model = build_model(desc)
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
