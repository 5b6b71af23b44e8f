"""Frames and serial chains of a Pinocchio model: tip lookup, the chain to a tip, model reduction.

An arm moves the joints of one serial chain (or any chosen set of joints); every other joint is
fixed with ``pin.buildReducedModel``. Real descriptions name a link and a fixed joint alike, so
a frame name may appear twice; :func:`frame_id` accepts that when both frames are at one place.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from .errors import AmbiguousFrame, FrameNotFound, JointNotFound, URDFError


def supporting_joints(model: pin.Model, frame_id: int) -> list[int]:
    """Ids of the moving joints on the chain from the root to a frame, base outwards."""
    joint = model.frames[frame_id].parentJoint
    return [j for j in model.supports[joint] if j > 0 and model.joints[j].nv > 0]


def joint_kind(joint) -> str:
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


def frame_id(model: pin.Model, tip: str) -> int:
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
    fid = frame_id(model, tip)
    names = [model.names[j] for j in range(1, model.njoints)]
    if joints is None:
        keep = supporting_joints(model, fid)
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


def active_q(full: pin.Model, reduced: pin.Model, q_full: np.ndarray) -> np.ndarray:
    """The entries of a full-model configuration that belong to the reduced model's joints."""
    return np.array(
        [
            q_full[full.joints[full.getJointId(reduced.names[j])].idx_q]
            for j in range(1, reduced.njoints)
            if reduced.joints[j].nv > 0
        ]
    )
