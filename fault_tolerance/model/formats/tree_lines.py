"""The tree lines ``inspect`` prints for a description, one function per kind of format.

A URDF (or xacro expansion) is listed as yourdfpy reads it, from the checked bytes only; an MJCF
description from the Pinocchio model its checked text builds (MJCF joint axes and ranges come from
``<default>`` classes, which Pinocchio has already resolved).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import URDFError
from fault_tolerance.model.chains import joint_kind


def urdf_tree_lines(desc, model: pin.Model) -> list[str]:
    """The links and joints of a checked URDF, its continuous and mimic joints, the leaf links."""
    return _urdf_lines(_yourdfpy_tree(desc.path, desc), desc)


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


def _urdf_lines(urdf, desc) -> list[str]:
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


def model_tree_lines(desc, model: pin.Model) -> list[str]:
    """The joints of the model (parent body -> child body, kind, axis, limits), the candidate tips."""
    bodies = {f.parentJoint: f.name for f in model.frames if f.type == pin.FrameType.BODY}
    lines = [
        f"model '{model.name}': {sum(f.type == pin.FrameType.BODY for f in model.frames)} "
        f"bodies, {model.njoints - 1} joints",
        "",
        "joints (parent -> child):",
    ]
    for j in range(1, model.njoints):
        joint = model.joints[j]
        parent = bodies.get(model.parents[j], "world") if model.parents[j] else "world"
        lim = ""
        if joint.nq == 1:
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            lim = f"  limits [{lo:.4g}, {hi:.4g}]"
        lines.append(
            f"  {model.names[j]:28s} {joint_kind(joint):10s} {parent} -> {bodies.get(j, '?')}{lim}"
        )
    if desc.mimic:
        lines.append(
            "joints that follow others (held fixed; they cannot be active joints): "
            + ", ".join(f"{a} follows {b}" for a, b in desc.mimic.items())
        )
    return lines + ["", f"candidate tip frames (leaf bodies, sites): {', '.join(desc.leaves)}"]
