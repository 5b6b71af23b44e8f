"""URDF trees: the structural checks Pinocchio does not make, and inspection (with yourdfpy).

The XML safety checks come first (:mod:`.urdf_xml`: size, UTF-8, no DTD or entities,
well-formed; importable from here as before). :func:`read_urdf` adds the structural checks
Pinocchio does not make (a link with two parents is silently mis-built, a zero joint axis
accepted) or makes with messages only on stderr (several root links, unknown links, unknown joint
types), and rewrites ``continuous`` joints as revolute joints with limits ±π, so the arm has one
coordinate per joint.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

from fault_tolerance.errors import URDFError
from fault_tolerance.model.formats.xml_safety import (
    _checked,
)

__all__ = [
    "MAX_URDF_JOINTS",
    "MOVING_JOINT_TYPES",
    "URDF_JOINT_TYPES",
    "URDFDescription",
    "default_tip",
    "native_reason",
    "native_stderr",
    "read_urdf",
]

#: Most joints accepted in one URDF. Pinocchio's URDF reader recurses along the tree (a chain of
#: ~4000 joints overflows an 8 MB stack and kills the process) and is quadratic in the number of
#: joints; the largest real robots have a few hundred.
MAX_URDF_JOINTS = 1000

#: Joint types of the URDF specification, and those an arm may move.
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVING_JOINT_TYPES = ("revolute", "continuous", "prismatic")


class URDFDescription(NamedTuple):
    """A URDF file that passed :func:`read_urdf`: the text Pinocchio reads and what it must be told."""

    path: Path
    data: bytes  # the file's bytes, checked (for yourdfpy)
    xml: str  # the checked XML with continuous joints rewritten as revolute ±π (for Pinocchio)
    joint_types: dict[str, str]  # joint name -> URDF type, as written in the file
    leaves: tuple[str, ...]  # links no joint starts from: the candidate tip frames
    mimic: dict[str, str]  # mimic joint -> the joint it follows
    continuous: tuple[str, ...]  # continuous joints, read as revolute with limits ±π
    unlimited: tuple[str, ...]  # continuous joints without velocity/effort limits (kept infinite)
    prefixes: tuple[str, ...] = ()  # undeclared XML namespace prefixes, declared to read the file


def read_urdf(path: str | Path, data: bytes | None = None) -> URDFDescription:
    """Check a URDF file (safety and tree structure) and prepare the XML Pinocchio will read.

    With ``data``, those bytes are checked instead of the file, and ``path`` only names them in
    messages (a URDF carried inside a saved run is read this way; no file is opened).

    Besides :func:`check_urdf_file`: every joint has a name, a URDF joint type, a parent and a child
    that are links of the file; no link is the child of two joints; exactly one link has no parent
    (the tree is connected and has no cycle); moving joints have a non-zero axis. ``continuous``
    joints become ``revolute`` with limits ``[-π, π]`` (their angle wraps; see ``posture.wrap``).

    Raises:
        URDFError: naming the file, the element and what is allowed.
    """
    path = Path(path)
    data, root, prefixes = _checked(path, data)
    where = str(path)
    links = _links(where, root)
    tree = _JointTree(links)
    for joint in root.findall("joint"):
        tree.add(where, joint)
    root_link = _root_link(where, links, tree.parent_of)
    _check_reachable(where, root_link, links, tree.parent_of, root)
    from lxml import etree

    xml = etree.tostring(root, encoding="unicode")
    leaves = tuple(lk for lk in links if lk not in tree.parents)
    return URDFDescription(
        path,
        data,
        xml,
        tree.types,
        leaves,
        tree.mimic,
        tuple(tree.continuous),
        tuple(tree.unlimited),
        prefixes,
    )


def _links(where: str, root) -> list[str]:
    """The robot's link names, after the checks of the ``<robot>`` element and its size."""
    if not root.get("name"):
        raise URDFError(f'{where}: <robot> has no name; a URDF starts with <robot name="...">')
    n_joints = len(root.findall("joint"))
    if n_joints > MAX_URDF_JOINTS:
        raise URDFError(f"{where}: {n_joints} joints; at most {MAX_URDF_JOINTS} are accepted")
    links = [lk.get("name") for lk in root.findall("link")]
    if any(not name for name in links):
        raise URDFError(f'{where}: a <link> has no name; every link needs name="..."')
    dup = sorted(n for n, k in Counter(links).items() if k > 1)
    if dup:
        raise URDFError(f"{where}: link(s) {dup} defined more than once; link names must be unique")
    return links


class _JointTree:
    """The joints read so far: types, which joint each link hangs from, mimic and continuous."""

    def __init__(self, links: list[str]) -> None:
        self.links, self.link_set = links, set(links)
        self.types: dict[str, str] = {}
        self.parent_of: dict[str, str] = {}  # child link -> joint
        self.parents: set[str] = set()
        self.mimic: dict[str, str] = {}
        self.continuous: list[str] = []
        self.unlimited: list[str] = []

    def add(self, where: str, joint) -> None:
        """Check one ``<joint>`` against the links and the joints before it, and record it."""
        name, jtype = self._name_and_type(where, joint)
        parent, child = _joint_ends(where, joint, name, self.links, self.link_set)
        if child in self.parent_of:
            raise URDFError(
                f"{where}: link '{child}' is the child of two joints ('{self.parent_of[child]}' "
                f"and '{name}'); a URDF is a tree: every link has at most one parent joint"
            )
        if child == parent:
            raise URDFError(f"{where}: joint '{name}' connects link '{child}' to itself")
        self.parent_of[child] = name
        self.parents.add(parent)
        if jtype in MOVING_JOINT_TYPES:
            _check_axis(where, name, joint.find("axis"))
            _check_limit(where, name, jtype, joint.find("limit"))
        el = joint.find("mimic")
        if el is not None:
            self.mimic[name] = el.get("joint") or "?"
        if jtype == "continuous":
            self.continuous.append(name)
            if _as_revolute(joint):
                self.unlimited.append(name)

    def _name_and_type(self, where: str, joint) -> tuple[str, str]:
        name = joint.get("name")
        if not name:
            raise URDFError(f'{where}: a <joint> has no name; every joint needs name="..."')
        if name in self.types:
            raise URDFError(
                f"{where}: joint '{name}' is defined more than once; joint names must be unique"
            )
        jtype = joint.get("type")
        if jtype not in URDF_JOINT_TYPES:
            raise URDFError(
                f"{where}: joint '{name}' has type {jtype!r}; URDF joint types are "
                f"{list(URDF_JOINT_TYPES)}"
            )
        self.types[name] = jtype
        return name, jtype


def _joint_ends(where: str, joint, name: str, links: list[str], link_set: set) -> tuple[str, str]:
    """The parent and child links of a joint, both links of the file."""
    ends: dict[str, str] = {}
    for end in ("parent", "child"):
        el = joint.find(end)
        link = None if el is None else el.get("link")
        if not link:
            raise URDFError(f"{where}: joint '{name}' has no <{end} link=\"...\"/>")
        ends[end] = link
        if ends[end] not in link_set:
            raise URDFError(
                f"{where}: joint '{name}' names {end} link '{ends[end]}', which is "
                f"not a <link> of the file; its links are {links}"
            )
    return ends["parent"], ends["child"]


def _root_link(where: str, links: list[str], parent_of: dict[str, str]) -> str:
    """The one link without a parent joint."""
    roots = [lk for lk in links if lk not in parent_of]
    if not links:
        raise URDFError(f"{where}: the robot has no <link>; a URDF needs at least one")
    if len(roots) > 1:
        raise URDFError(
            f"{where}: the tree is not connected: links {roots} have no parent joint; "
            "a URDF has exactly one root link, every other link is the child of a joint"
        )
    if not roots:
        raise URDFError(f"{where}: no root link: the joints form a cycle; a URDF must be a tree")
    return roots[0]


def _check_axis(where: str, name: str, axis) -> None:
    if axis is None or axis.get("xyz") is None:
        return  # URDF's default axis is (1, 0, 0)
    try:
        xyz = [float(v) for v in axis.get("xyz").split()]
    except ValueError:
        xyz = []
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise URDFError(
            f"{where}: joint '{name}' has axis xyz=\"{axis.get('xyz')}\"; an axis is "
            "three finite numbers"
        )
    if math.hypot(*xyz) < 1e-9:
        raise URDFError(
            f"{where}: joint '{name}' has a zero axis; a moving joint needs a non-zero axis"
        )


def _check_limit(where: str, name: str, jtype: str, limit) -> None:
    """``<limit>`` numbers: lower <= upper (finite), velocity and effort >= 0."""
    if limit is None:
        return
    vals = {}
    keys = (
        ("velocity", "effort")
        if jtype == "continuous"
        else ("lower", "upper", "velocity", "effort")
    )
    for key in keys:  # a continuous joint's lower / upper are ignored (read as ±π)
        text = limit.get(key)
        if text is None:
            continue
        try:
            vals[key] = float(text)
        except ValueError:
            vals[key] = math.nan
        if math.isnan(vals[key]) or (key in ("lower", "upper") and not math.isfinite(vals[key])):
            raise URDFError(
                f"{where}: joint '{name}' has <limit {key}=\"{text}\">; it must be a finite number"
            )
        if key in ("velocity", "effort") and vals[key] < 0:
            raise URDFError(
                f"{where}: joint '{name}' has <limit {key}=\"{text}\">; it must be >= 0"
            )
    if vals.get("lower", 0.0) > vals.get("upper", 0.0):
        raise URDFError(
            f"{where}: joint '{name}' has lower limit {vals.get('lower', 0.0)} > upper limit "
            f"{vals.get('upper', 0.0)}; lower must be <= upper"
        )


def _check_reachable(where, root_link, links, parent_of, root) -> None:
    """Every link hangs from the root (no cycle detached from the tree)."""
    child_of: dict[str, list[str]] = {}
    for joint in root.findall("joint"):
        child_of.setdefault(joint.find("parent").get("link"), []).append(
            joint.find("child").get("link")
        )
    seen, stack = {root_link}, [root_link]
    while stack:
        for c in child_of.get(stack.pop(), []):
            if c not in seen:
                seen.add(c)
                stack.append(c)
    lost = [lk for lk in links if lk not in seen]
    if lost:
        raise URDFError(
            f"{where}: links {lost} are not connected to the root link '{root_link}' "
            "(their joints form a cycle); a URDF must be a tree"
        )


def _as_revolute(joint) -> bool:
    """Rewrite a continuous joint as revolute with limits ±π; True if it had no velocity/effort limit."""
    from lxml import etree

    joint.set("type", "revolute")
    limit = joint.find("limit")
    unlimited = limit is None or limit.get("velocity") is None or limit.get("effort") is None
    if limit is None:
        limit = etree.SubElement(joint, "limit")
    limit.set("lower", repr(-math.pi))
    limit.set("upper", repr(math.pi))
    for key in ("velocity", "effort"):
        if limit.get(key) is None:
            limit.set(
                key, "0"
            )  # set to infinity after Pinocchio has read it (urdfdom needs a number)
    return unlimited


def default_tip(description: URDFDescription) -> str:
    """The tip frame when none is named: the only leaf link, else a :class:`URDFError` listing them."""
    leaves = description.leaves
    if len(leaves) == 1:
        return leaves[0]
    raise URDFError(
        f"{description.path}: no tip frame given and the tree has {len(leaves)} leaf links "
        f"{list(leaves)}; name the tip frame (tip=..., --tip)"
    )


@contextlib.contextmanager
def native_stderr() -> Iterator[list[str]]:
    """Capture what native code writes to file descriptor 2 while the block runs.

    urdfdom reports its parse errors with console_bridge on stderr and Pinocchio then raises only
    "does not contain a valid URDF model"; the captured lines (filled when the block ends) carry the
    reason, and the command line keeps its one-line error messages.
    """
    lines: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to capture
        yield lines
        return
    with tempfile.TemporaryFile() as tmp:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines.extend(
                s.strip() for s in tmp.read().decode("utf-8", "replace").splitlines() if s.strip()
            )


def native_reason(lines: list[str]) -> str:
    """The error lines urdfdom printed, in one line, without their source locations."""
    keep = [s.removeprefix("Error:").strip() for s in lines if not s.startswith("at line ")]
    return "; ".join(k for k in keep if k)
