"""Pinocchio models from checked URDF text: the kinematic model and its visual geometry.

Pinocchio reads only text that passed :func:`~.urdf.read_urdf`, never the file again, and its
errors (``ValueError`` / ``RuntimeError`` with C++ messages, plus urdfdom's lines on stderr) are
turned into :class:`~.errors.URDFError` here, at the boundary.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from .errors import URDFError
from .urdf import URDFDescription, native_reason, native_stderr, read_urdf


def load_urdf_models(
    path: Path, package_dirs: Sequence[str] | None
) -> tuple[pin.Model, pin.GeometryModel | None, URDFDescription]:
    """Model, visual geometry and :class:`~.urdf.URDFDescription` of a URDF file.

    Meshes that cannot be found (``package://`` without ``package_dirs``) drop the visual
    geometry with a warning: the kinematics does not need it.
    """
    desc = read_urdf(path)
    model = build_model(desc)
    visual = build_visuals(model, desc, package_dirs)
    return model, visual, desc


def build_model(desc: URDFDescription) -> pin.Model:
    """The kinematic model of a checked description (continuous joints without limits unlimited)."""
    failure = None
    with native_stderr() as log:
        try:
            model = pin.buildModelFromXML(desc.xml)
        except Exception as err:  # Pinocchio raises ValueError / RuntimeError with C++ messages
            failure = err
    if failure is not None:
        reason = native_reason(log) or str(failure)
        raise URDFError(
            f"{desc.path}: Pinocchio could not build a model from it: {reason}"
        ) from failure
    if desc.unlimited:  # continuous joints without <limit>: no velocity or effort limit
        vel, eff = model.velocityLimit.copy(), model.effortLimit.copy()
        for joint in desc.unlimited:
            idx = model.joints[model.getJointId(joint)].idx_v
            vel[idx] = eff[idx] = np.inf
        model.velocityLimit, model.effortLimit = vel, eff
    return model


def build_visuals(
    model: pin.Model, desc: URDFDescription, package_dirs: Sequence[str] | None
) -> pin.GeometryModel | None:
    """Visual geometry of a description, or ``None`` with a warning when it cannot be read."""
    dirs = [str(d) for d in (package_dirs or [])] + [str(Path(desc.path).parent)]
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
            f"{desc.path}: visual geometry not loaded ({native_reason(log) or failure}); the arm "
            "works without it, the replay shows no meshes. Pass package_dirs (--package-dir) "
            "where package:// meshes live.",
            stacklevel=4,
        )
        visual = None
    return visual
