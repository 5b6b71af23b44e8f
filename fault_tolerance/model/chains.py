"""Frames and serial chains of a Pinocchio model: tip lookup, the chain to a tip, model reduction.

An arm moves the joints of one serial chain (or any chosen set of joints); every other joint is
fixed with ``pin.buildReducedModel``. Real descriptions name a link and a fixed joint alike, so
a frame name may appear twice; :func:`frame_id` accepts that when both frames are at one place,
and :func:`reduce_model` makes the names unique while Pinocchio reduces the model (its lookups
by name take no frame type), then gives them back.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from fault_tolerance.errors import AmbiguousFrame, FrameNotFound, JointNotFound, URDFError


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


def frame_id(model: pin.Model, tip: str, *, warn: bool = False, label: str = "") -> int:
    """Id of the frame named ``tip``.

    Real descriptions often give a link and a joint the same name, so Pinocchio has two frames
    of that name. Both at one place (a fixed joint and its child link): either serves, the
    link's is returned. At different places: the link's (a tip is a link), with a warning if
    ``warn``. Several frames of the name and no link among them: :class:`AmbiguousFrame`.
    """
    ids = [i for i, f in enumerate(model.frames) if f.name == tip]
    if not ids:
        raise FrameNotFound(tip, [f.name for f in model.frames])
    if len(ids) == 1:
        return ids[0]
    first = model.frames[ids[0]]
    bodies = [i for i in ids if model.frames[i].type == pin.FrameType.BODY]
    if all(
        model.frames[i].parentJoint == first.parentJoint
        and model.frames[i].placement.isApprox(first.placement)
        for i in ids[1:]
    ):
        return bodies[0] if bodies else ids[0]
    described = [
        f"{model.frames[i].name} ({model.frames[i].type.name} on joint "
        f"'{model.names[model.frames[i].parentJoint]}')"
        for i in ids
    ]
    if len(bodies) == 1:
        if warn:
            warnings.warn(
                f"{label + ': ' if label else ''}frame name '{tip}' is carried by {len(ids)} frames at different places "
                f"({', '.join(described)}); the tip is the link '{tip}'",
                stacklevel=3,
            )
        return bodies[0]
    raise AmbiguousFrame(tip, described)


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
    fid = frame_id(model, tip, warn=True, label=label)
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
    # buildReducedModel looks frames up by name without a FrameType (a locked joint's frame, a
    # frame's parent, a geometry's frame): any name two frames share (a link and a joint of one
    # name, as in Baxter's `left_hand`) makes that lookup ambiguous, a raw ValueError. So every
    # frame name is made unique meanwhile, and restored in both models afterwards.
    unique_frame_names(model)
    try:
        if visual_model is None:
            reduced, geom = pin.buildReducedModel(model, lock, q_ref), None
        else:
            reduced, geoms = pin.buildReducedModel(model, [visual_model], lock, q_ref)
            geom = geoms[0]
    except Exception as err:  # Pinocchio's ValueError/RuntimeError: never raw to the user
        raise URDFError(
            f"{label or model.name}: Pinocchio could not fix the joints outside the arm: {err}"
        ) from err
    finally:
        restore_frame_names(model)
    restore_frame_names(reduced)
    return reduced, geom


_RENAMED = "\x00frame"  # marks a temporary frame name; no URDF, MJCF or xacro name holds a NUL

#: Which frame of a shared name keeps it while the names are made unique (lower first): a
#: joint's frame, so that Pinocchio's lookups of the joints it fixes find it.
_KEEPS_NAME = {pin.FrameType.JOINT: 0, pin.FrameType.FIXED_JOINT: 1, pin.FrameType.BODY: 2}


def unique_frame_names(model: pin.Model) -> int:
    """Give every frame whose name another frame also carries a temporary unique name.

    Of the frames sharing a name, the joint's frame keeps it (then a fixed joint's, then a
    link's, then the first); the others get ``name`` plus a NUL-marked suffix and a counter.
    Undone by :func:`restore_frame_names` (on the model and on what was built from it). Returns
    how many frames were renamed.
    """
    by_name: dict[str, list[int]] = {}
    for i, f in enumerate(model.frames):
        by_name.setdefault(f.name, []).append(i)
    renamed = 0
    for ids in by_name.values():
        if len(ids) < 2:
            continue
        keep = min(ids, key=lambda i: (_KEEPS_NAME.get(model.frames[i].type, 3), i))
        for k, i in enumerate(i for i in ids if i != keep):
            f = model.frames[i]
            f.name = f"{f.name}{_RENAMED}{k}"
            model.frames[i] = f
            renamed += 1
    return renamed


def restore_frame_names(model: pin.Model) -> None:
    """Undo :func:`unique_frame_names`: strip the temporary suffix from every frame name."""
    for i, f in enumerate(model.frames):
        if _RENAMED in f.name:
            f.name = f.name[: f.name.index(_RENAMED)]
            model.frames[i] = f


def active_q(full: pin.Model, reduced: pin.Model, q_full: np.ndarray) -> np.ndarray:
    """The entries of a full-model configuration that belong to the reduced model's joints."""
    return np.array(
        [
            q_full[full.joints[full.getJointId(reduced.names[j])].idx_q]
            for j in range(1, reduced.njoints)
            if reduced.joints[j].nv > 0
        ]
    )


class SerialChain(NamedTuple):
    """The moving joints from the root to some leaf links, and the tip suggested for them."""

    tip: str  # the suggested tip frame (a leaf link)
    joints: tuple[str, ...]  # moving joints from the root outwards, mimic joints left out
    ends: tuple[str, ...]  # every leaf link this chain serves (tip included)

    def option(self) -> str:
        """The command-line options selecting this chain."""
        return f"--tip {self.tip} --joints {','.join(self.joints)}"


#: Name fragments of links that are end effectors rather than sensors (the suggested tips).
TIP_WORDS = ("tcp", "tool", "eef", "end_effector", "ee_link", "flange", "gripper", "hand", "wrist")


def serial_chains(
    model: pin.Model, leaves: Sequence[str], mimic: Sequence[str] = (), min_joints: int = 1
) -> list[SerialChain]:
    """The serial chains of a tree: leaf links grouped by their moving joints from the root.

    A two-arm robot, a mobile manipulator or an arm with a gripper has many leaf links
    (fingers, sensors, wheels); leaves reached through the same moving joints form one chain.
    Mimic joints are left out (they follow another joint; an arm cannot move them freely).
    Chains with fewer than ``min_joints`` joints are dropped; longest chains first.
    """
    groups: dict[tuple[str, ...], list[str]] = {}
    skip = set(mimic)
    for leaf in leaves:
        ids = [i for i, f in enumerate(model.frames) if f.name == leaf]
        if not ids:
            continue
        body = next((i for i in ids if model.frames[i].type == pin.FrameType.BODY), ids[0])
        joints = tuple(
            model.names[j] for j in supporting_joints(model, body) if model.names[j] not in skip
        )
        if len(joints) >= min_joints:
            groups.setdefault(joints, []).append(leaf)
    chains = [
        SerialChain(_suggested_tip(ends), joints, tuple(ends)) for joints, ends in groups.items()
    ]
    return sorted(chains, key=lambda c: (-len(c.joints), c.tip))


def _suggested_tip(ends: Sequence[str]) -> str:
    """The end-effector-like name among leaves (``*_tcp``, ``tool0``, ``*_gripper``...), else the first."""
    for word in TIP_WORDS:
        for end in ends:
            if word in end.lower():
                return end
    return ends[0]
