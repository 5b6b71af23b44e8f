"""Pinocchio models from checked URDF text: the kinematic model and its visual geometry.

Pinocchio reads only text that passed :func:`~.urdf.read_urdf`, never the file again, and its
errors (``ValueError`` / ``RuntimeError`` with C++ messages, plus urdfdom's lines on stderr) are
turned into :class:`~.errors.URDFError` here, at the boundary.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin
from lxml import etree

from fault_tolerance.errors import MeshRefused, URDFError
from fault_tolerance.model.formats.packages import locate_mesh
from fault_tolerance.model.formats.urdf import (
    URDFDescription,
    native_reason,
    native_stderr,
    read_urdf,
)
from fault_tolerance.model.formats.xacro import expand_xacro, is_xacro
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

    Meshes are opened only inside the description's folder and ``package_dirs``
    (:func:`~.packages.locate_mesh`). One warning lists the meshes left out as missing or
    unreadable, another those refused (outside the folders); the model may then hold no geometry.
    """
    root = _parse_safely(desc.path, desc.xml.encode("utf-8"))
    base = Path(desc.path).parent
    missing, refused = _resolve_meshes(root, [base, *(package_dirs or [])], base)
    visual, unreadable = _geometry(model, root)
    dropped = missing + unreadable
    if dropped:
        warnings.warn(
            f"{desc.path}: {_count(dropped)} mesh file(s) not found or unreadable, their visuals "
            f"are left out (the kinematics does not need them): {_shown(dropped)}; pass "
            "--package-dir (package_dirs=[...]) where package:// meshes live",
            stacklevel=4,
        )
    if refused:
        warnings.warn(
            f"{desc.path}: {_count(refused)} mesh(es) not opened, their visuals are left out: "
            f"{_shown(refused)}",
            stacklevel=4,
        )
    return visual


def _count(names: Sequence[str]) -> int:
    return len(set(names))


def _shown(names: Sequence[str]) -> str:
    names = sorted(set(names))
    return ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")


def _geometry(model: pin.Model, root) -> tuple[pin.GeometryModel | None, list[str]]:
    """Pinocchio's visual geometry of a URDF tree whose mesh names are resolved paths.

    A mesh that coal/assimp cannot read drops its visuals and the build is tried again; returns
    the geometry and the mesh names so dropped.
    """
    dropped: list[str] = []
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
            return visual, dropped
        bad = _unreadable_mesh(root, f"{failure} {native_reason(log)}")
        if bad is None:
            dropped += _drop(root, lambda el: el.find("geometry/mesh") is not None)
            continue
        dropped += _drop(root, lambda el, bad=bad: _mesh_of(el) == bad)
    return None, dropped  # pragma: no cover - every mesh visual dropped and still failing


def _mesh_of(visual) -> str | None:
    mesh = visual.find("geometry/mesh")
    return None if mesh is None else mesh.get("filename")


def _resolve_meshes(root, roots: Sequence[str | Path], base: Path | None) -> tuple[list, list]:
    """Rewrite each mesh name as its file (:func:`~.packages.locate_mesh`) or drop its visual.

    Returns the names dropped as missing (no such file or package) and those refused (outside
    ``roots``), the latter with the reason.
    """
    missing: list[str] = []
    refused: list[str] = []
    for visual in root.findall("link/visual"):
        mesh = visual.find("geometry/mesh")
        if mesh is None:
            continue
        uri = mesh.get("filename") or ""
        try:
            mesh.set("filename", str(locate_mesh(uri, roots, base)))
        except MeshRefused as err:
            refused.append(str(err))
            visual.getparent().remove(visual)
        except URDFError:  # MeshNotFound, PackageNotFound
            missing.append(uri or "(no filename)")
            visual.getparent().remove(visual)
    return missing, refused


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
    visual, _ = _geometry(model, _parse_safely(desc.path, xml.encode("utf-8")))
    return visual, dropped  # a mesh that fails to load: drawn without it


def confine_meshes(xml: str, roots: Sequence[Path]) -> tuple[str, list[str]]:
    """``xml`` with each mesh name resolved inside ``roots``, or its ``<visual>`` dropped.

    The names are read as the loader reads them (:func:`~.packages.locate_mesh`: ``package://``,
    ``file://``, absolute and relative names, normalised), except that a run carries no folder of
    its description: a relative name is tried against each root. Returns the new XML and the
    names refused or not found, each with the reason. ``<collision>`` elements are removed
    (never drawn).
    """
    root = _parse_safely(Path("carried URDF"), xml.encode("utf-8"))
    for link in root.findall("link"):
        for col in link.findall("collision"):
            link.remove(col)
    missing, refused = _resolve_meshes(root, [Path(r) for r in roots], None)
    return etree.tostring(root, encoding="unicode"), refused + [
        f"{m[:80]!r}: not found inside the package folders given" for m in missing
    ]
