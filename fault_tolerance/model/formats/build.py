"""Pinocchio models from checked URDF text: the kinematic model and its visual geometry.

Pinocchio reads only text that passed :func:`~.urdf.read_urdf`, never the file again, and its
errors (``ValueError`` / ``RuntimeError`` with C++ messages, plus urdfdom's lines on stderr) are
turned into :class:`~.errors.URDFError` here, at the boundary.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
from lxml import etree

from fault_tolerance.errors import PackageNotFound, URDFError
from fault_tolerance.model.formats.urdf import (
    URDFDescription,
    native_reason,
    native_stderr,
    read_urdf,
)
from fault_tolerance.model.formats.xacro import expand_xacro, is_xacro, resolve_uri
from fault_tolerance.model.formats.xml_safety import _parse_safely, prefix_notice


def load_urdf_models(
    path: Path, package_dirs: Sequence[str] | None, xacro_args: Mapping[str, str] | None = None
) -> tuple[pin.Model, pin.GeometryModel | None, URDFDescription]:
    """Model, visual geometry and :class:`~.urdf.URDFDescription` of a URDF or xacro file.

    Meshes that cannot be found or read drop only their own visuals, with one warning.
    """
    desc = read_description(path, package_dirs, xacro_args)
    model = build_model(desc)
    visual = build_visuals(model, desc, package_dirs)
    return model, visual, desc


def read_description(
    path: Path,
    package_dirs: Sequence[str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
) -> URDFDescription:
    """The checked description of a URDF file, or of a xacro file after expansion.

    Undeclared namespace prefixes and xacro's notices give one warning each.
    """
    path = Path(path)
    read = read_xacro_file if is_xacro(path) else read_urdf_file
    return read(path, package_dirs, xacro_args)


def read_urdf_file(
    path: Path,
    package_dirs: Sequence[str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
) -> URDFDescription:
    """The checked description of a URDF file (the ``urdf`` format's reader)."""
    path = Path(path)
    if xacro_args:
        raise URDFError(
            f"{path}: xacro arguments {sorted(xacro_args)} given for a file that is not a "
            "xacro file (.xacro, .urdf.xacro)"
        )
    return _with_prefix_notice(read_urdf(path))


def read_xacro_file(
    path: Path,
    package_dirs: Sequence[str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
) -> URDFDescription:
    """The checked URDF a xacro file expands to (the ``xacro`` format's reader)."""
    path = Path(path)
    if not path.is_file():
        raise URDFError(f"{path}: no such xacro file")
    data, notices = expand_xacro(path, package_dirs, xacro_args)
    for note in dict.fromkeys(notices):
        warnings.warn(f"{path}: xacro: {note}", stacklevel=4)
    return _with_prefix_notice(read_urdf(path, data))


def _with_prefix_notice(desc: URDFDescription) -> URDFDescription:
    if desc.prefixes:
        warnings.warn(prefix_notice(str(desc.path), desc.prefixes), stacklevel=5)
    return desc


def urdf_from_text(label: Path, data: bytes) -> URDFDescription:
    """The description of a stored URDF text (an arm record), checked again like a file."""
    return read_urdf(label, data)


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
    """Visual geometry of a description; visuals whose mesh is missing or unreadable are left out.

    One warning lists the meshes left out (the model may then hold no geometry at all).
    """
    root = _parse_safely(desc.path, desc.xml.encode("utf-8"))
    dropped = _resolve_meshes(root, package_dirs, Path(desc.path).parent)
    for _ in range(len(root.findall("link/visual")) + 1):
        failure = None
        with native_stderr() as log, warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # Pinocchio's notice about package dirs
            try:
                visual = pin.buildGeomFromUrdfString(
                    model, etree.tostring(root, encoding="unicode"), pin.GeometryType.VISUAL
                )
            except Exception as err:  # coal/assimp raise ValueError with C++ messages
                failure = err
        if failure is None:
            break
        bad = _unreadable_mesh(root, f"{failure} {native_reason(log)}")
        if bad is None:
            dropped += _drop(root, lambda el: el.find("geometry/mesh") is not None)
            continue
        dropped += _drop(root, lambda el, bad=bad: _mesh_of(el) == bad)
    else:  # pragma: no cover - every mesh visual dropped and still failing
        visual = None
    if dropped:
        names = sorted(set(dropped))
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        warnings.warn(
            f"{desc.path}: {len(names)} mesh file(s) not found or unreadable, their visuals are "
            f"left out (the kinematics does not need them): {shown}; pass --package-dir "
            "(package_dirs=[...]) where package:// meshes live",
            stacklevel=4,
        )
    return visual


def _mesh_of(visual) -> str | None:
    mesh = visual.find("geometry/mesh")
    return None if mesh is None else mesh.get("filename")


def _resolve_meshes(root, package_dirs: Sequence[str] | None, base: Path) -> list[str]:
    """Rewrite mesh filenames as absolute paths; drop the visuals whose mesh does not exist."""
    missing: list[str] = []
    for visual in root.findall("link/visual"):
        mesh = visual.find("geometry/mesh")
        if mesh is None:
            continue
        uri = mesh.get("filename") or ""
        try:
            path = resolve_uri(uri, package_dirs, base)
        except PackageNotFound:
            path = None
        if path is None or not path.is_file():
            missing.append(uri or "(no filename)")
            visual.getparent().remove(visual)
        else:
            mesh.set("filename", str(path.resolve()))
    return missing


def _unreadable_mesh(root, message: str) -> str | None:
    """The mesh path an error message names, if it is one of the file's meshes."""
    for visual in root.findall("link/visual"):
        path = _mesh_of(visual)
        if path and path in message:
            return path
    return None


def _drop(root, which) -> list[str]:
    out = []
    for visual in root.findall("link/visual"):
        if which(visual):
            out.append(_mesh_of(visual) or "?")
            visual.getparent().remove(visual)
    return out


def confined_visuals(
    model: pin.Model, desc: URDFDescription, roots: Sequence[Path]
) -> tuple[pin.GeometryModel | None, list[str]]:
    """Visuals of a stored URDF text whose meshes are opened only inside ``roots``.

    Returns the geometry and the refused mesh names with the reason (:func:`confine_meshes`).
    """
    xml, dropped = confine_meshes(desc.xml, roots)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a mesh that fails to load: drawn without visuals
        visual = build_visuals(model, desc._replace(xml=xml), [])
    return visual, dropped


def confine_meshes(xml: str, roots: Sequence[Path]) -> tuple[str, list[str]]:
    """``xml`` with each mesh name resolved inside ``roots``, or its ``<visual>`` dropped.

    A ``<mesh filename="package://PKG/REST">`` is replaced by the real path of ``ROOT/PKG/REST``
    (or of ``ROOT/REST`` when ``ROOT`` is the package folder ``PKG`` itself) for the first root where
    that is a file inside ``ROOT`` after links are followed. Returns the new XML and a list saying
    which names were refused and why. ``<collision>`` elements are removed (never drawn).
    """
    root = _parse_safely(Path("carried URDF"), xml.encode("utf-8"))
    real_roots = [Path(os.path.realpath(r)) for r in roots if Path(r).is_dir()]
    dropped: list[str] = []
    for link in root.findall("link"):
        for col in link.findall("collision"):
            link.remove(col)
        for vis in link.findall("visual"):
            for mesh in vis.iter("mesh"):
                name = mesh.get("filename") or ""
                found, why = _resolve_mesh(name, real_roots)
                if found is None:
                    dropped.append(f"{name[:80]!r}: {why}")
                    link.remove(vis)
                    break
                mesh.set("filename", str(found))
    return etree.tostring(root, encoding="unicode"), dropped


def _resolve_mesh(name: str, roots: Sequence[Path]) -> tuple[Path | None, str]:
    prefix = "package://"
    if not name.startswith(prefix):
        return None, "not a package:// name"
    rel = name[len(prefix) :]
    parts = rel.split("/")
    if not rel or "\\" in rel or "\x00" in rel or any(p in ("", ".", "..") for p in parts):
        return None, "'..', '.', empty or backslash components are not allowed"
    for real in roots:
        tails = [parts] + ([parts[1:]] if real.name == parts[0] and len(parts) > 1 else [])
        for tail in tails:
            candidate = Path(os.path.realpath(real.joinpath(*tail)))
            if candidate.is_file() and candidate.is_relative_to(real):
                return candidate, ""
    return None, "not found inside the package folders given"
