"""URDF files: safe reading and inspection (with yourdfpy).

URDF is XML, and XML can carry document type declarations whose entities expand to gigabytes
("billion laughs") or pull in local files and URLs (external entities). A URDF never needs
either, so :func:`check_urdf_file` refuses any file with a ``<!DOCTYPE`` or ``<!ENTITY`` before
Pinocchio's or yourdfpy's parser sees it, and parses the rest with entity resolution and network
access switched off.
"""

from __future__ import annotations

import re
from pathlib import Path

from .errors import URDFError

#: Largest URDF file accepted [bytes]; real robot descriptions are far smaller.
MAX_URDF_BYTES = 20 * 1024 * 1024

_DTD = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


def check_urdf_file(path: str | Path) -> bytes:
    """Return the bytes of a URDF file after checking it is safe, well-formed XML with a ``<robot>``.

    Raises:
        URDFError: naming the file and the problem (missing, too large, DTD/entities, malformed XML,
            root element not ``robot``).
    """
    path = Path(path)
    if not path.is_file():
        raise URDFError(f"{path}: no such URDF file")
    size = path.stat().st_size
    if size > MAX_URDF_BYTES:
        raise URDFError(f"{path}: {size} bytes is larger than the {MAX_URDF_BYTES} bytes allowed")
    data = path.read_bytes()
    if _DTD.search(data):
        raise URDFError(
            f"{path}: document type declarations and entities (<!DOCTYPE>, <!ENTITY>) are not "
            "allowed in a URDF; they are refused to rule out entity expansion and external entities"
        )
    root = _parse_safely(path, data)
    if root.tag != "robot":
        raise URDFError(f"{path}: the root element is <{root.tag}>, a URDF needs <robot>")
    return data


def _parse_safely(path: Path, data: bytes):
    """Parse XML with lxml, entities unresolved, no network, no huge trees."""
    from lxml import etree

    parser = etree.XMLParser(
        resolve_entities=False, no_network=True, huge_tree=False, load_dtd=False, dtd_validation=False
    )
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        raise URDFError(f"{path}: not well-formed XML: {err}") from err


def urdf_path_of(target: str) -> Path:
    """The URDF file behind a catalog name, an example-robot-data name or a path."""
    from .arm import catalog, example_robot_names, robot_path

    if target in catalog():
        return robot_path(catalog()[target]["urdf"])
    if target in example_robot_names():
        from example_robot_data.robots_loader import ROBOTS

        loader = ROBOTS[target]
        sub = Path(loader.path) / loader.urdf_subpath / loader.urdf_filename
        from example_robot_data.robots_loader import getModelPath

        return Path(getModelPath(str(sub))) / sub
    return Path(target)


def inspect_text(
    target: str,
    *,
    tip: str | None = None,
    task=None,
    joints=None,
    package_dirs=None,
) -> str:
    """A readable description of a robot: the URDF tree (read with yourdfpy), chain, task, intolerable joints."""
    import numpy as np
    import yourdfpy

    from .arm import load_arm
    from .failures import scenarios
    from .linalg import PIVOT_TOL, projection

    path = urdf_path_of(target)
    check_urdf_file(path)
    try:
        urdf = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=False,
                                  build_collision_scene_graph=False)
    except Exception as err:  # yourdfpy raises many types
        raise URDFError(f"{path}: yourdfpy could not read it: {err}") from err
    lines = [f"{target}: {path}", f"robot '{urdf.robot.name}': {len(urdf.robot.links)} links, "
             f"{len(urdf.robot.joints)} joints", "", "joints (parent -> child):"]
    for j in urdf.robot.joints:
        lim = ""
        if j.limit is not None and j.type in ("revolute", "prismatic"):
            lim = f"  limits [{j.limit.lower:.4g}, {j.limit.upper:.4g}], velocity {j.limit.velocity}"
        axis = "" if j.type == "fixed" or j.axis is None else f"  axis {np.round(j.axis, 3).tolist()}"
        lines.append(f"  {j.name:28s} {j.type:10s} {j.parent} -> {j.child}{axis}{lim}")
    parents = {j.parent for j in urdf.robot.joints}
    leaves = [lk.name for lk in urdf.robot.links if lk.name not in parents]
    lines += ["", f"candidate tip frames (leaf links): {', '.join(leaves)}"]
    arm = load_arm(target, tip=tip, task=task, joints=joints, package_dirs=package_dirs)
    lines += [
        "", f"chain to tip '{arm.tip}': {' -> '.join(arm.joint_names)}",
        f"task {'/'.join(arm.task)}: n = {arm.n}, m = {arm.m}, redundancy r = {arm.redundancy}",
    ]
    q = arm.q_reference
    J = arm.jacobian(q)
    proj = projection(J)
    label = "reference" if np.any(q != arm.neutral()) else "neutral"
    lines.append(f"at the {label} configuration {np.round(q, 4).tolist()}: "
                 f"σ_min(J) = {proj.sigma_min:.3g}" + ("  (singular)" if proj.sigma_min < 1e-6 else ""))
    if arm.redundancy >= 1:
        sc = scenarios("all", arm.n, r=arm.redundancy, joint_names=arm.joint_names)
        bad = [arm.joint_names[i] for i in sc.columns if proj.N[i, i] < PIVOT_TOL]
        lines.append("intolerable joints there (locking one loses the task): "
                     + (", ".join(bad) if bad else "none"))
    else:
        lines.append("not redundant for this task: any locked joint loses it")
    return "\n".join(lines)
