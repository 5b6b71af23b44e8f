"""URDF files: safe reading, structural checks and inspection (with yourdfpy).

URDF is XML, and XML can carry document type declarations whose entities expand to gigabytes
("billion laughs") or pull in local files and URLs (external entities). A URDF never needs
either. :func:`check_urdf_file` therefore refuses any file that is not UTF-8, is too large, or has
a ``<!DOCTYPE``/``<!ENTITY`` (checked on the raw bytes *and* on the parsed document, so another
declared encoding cannot hide one), and parses the rest with lxml with entity resolution, DTD
loading and network access switched off. Every later parser gets the bytes (or text) that passed
these checks, never the file again:

* Pinocchio (urdfdom on tinyxml2) ignores DTDs altogether and expands no entity;
* yourdfpy (lxml with its default parser, falling back to a *recovering* parser on errors) would
  resolve internal entities, so it must only ever see checked bytes.

:func:`read_urdf` adds the structural checks Pinocchio does not make (a link with two parents is
silently mis-built, a zero joint axis accepted) or makes with messages only on stderr (several root
links, unknown links, unknown joint types), and rewrites ``continuous`` joints as revolute joints
with limits ±π, so the arm has one coordinate per joint.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import tempfile
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

from .errors import URDFError

#: Largest URDF file accepted [bytes]; real robot descriptions are far smaller.
MAX_URDF_BYTES = 20 * 1024 * 1024
#: Most joints accepted in one URDF. Pinocchio's URDF reader recurses along the tree (a chain of
#: ~4000 joints overflows an 8 MB stack and kills the process) and is quadratic in the number of
#: joints; the largest real robots have a few hundred.
MAX_URDF_JOINTS = 1000

#: Joint types of the URDF specification, and those an arm may move.
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVING_JOINT_TYPES = ("revolute", "continuous", "prismatic")

_DTD = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_BOMS = (b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff", b"\xff\xfe\x00\x00")


def check_urdf_file(path: str | Path) -> bytes:
    """Return the bytes of a URDF file after checking it is safe, well-formed XML with a ``<robot>``.

    Raises:
        URDFError: naming the file and the problem (missing, too large, not UTF-8, DTD/entities,
            malformed XML, root element not ``robot``).
    """
    return _checked(Path(path))[0]


def _checked(path: Path, data: bytes | None = None):
    """The bytes (prefixes declared), the lxml root element and the undeclared prefixes.

    ``data`` is the text to check in place of the file's (a xacro expansion of ``path``).
    """
    if data is None:
        if not path.is_file():
            raise URDFError(f"{path}: no such URDF file")
        size = path.stat().st_size
        if size > MAX_URDF_BYTES:
            raise URDFError(
                f"{path}: {size} bytes is larger than the {MAX_URDF_BYTES} bytes allowed"
            )
        data = path.read_bytes()
    data, prefixes, root = _checked_bytes(data, str(path))
    if root.tag != "robot":
        raise URDFError(f"{path}: the root element is <{root.tag}>, a URDF needs <robot>")
    return data, root, prefixes


def check_bytes(
    data: bytes, where: str, *, require_robot: bool = True
) -> tuple[bytes, tuple[str, ...]]:
    """Safety checks of XML bytes (size, UTF-8, no DTD/entities, well-formed).

    Returns the bytes, with a declaration added for each namespace prefix the text uses but never
    declares (Gazebo/ROS extensions such as ``<gazebo:plugin>``; URDF readers ignore those
    elements), and the prefixes so declared. ``where`` names the source in errors.
    """
    data, prefixes, root = _checked_bytes(data, where)
    if require_robot and root.tag != "robot":
        raise URDFError(f"{where}: the root element is <{root.tag}>, a URDF needs <robot>")
    return data, prefixes


def _checked_bytes(data: bytes, where: str):
    if len(data) > MAX_URDF_BYTES:
        raise URDFError(
            f"{where}: {len(data)} bytes is larger than the {MAX_URDF_BYTES} bytes allowed"
        )
    if data.startswith(_BOMS) or b"\x00" in data:
        raise URDFError(f"{where}: not UTF-8 text (UTF-16/32 or binary); a URDF must be UTF-8")
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise URDFError(
            f"{where}: not UTF-8 text (invalid byte at offset {err.start}); a URDF must be UTF-8"
        ) from None
    if _DTD.search(data):
        raise URDFError(_DTD_MESSAGE.format(path=where))
    data, prefixes, root = _parse_declaring_prefixes(where, data)
    docinfo = root.getroottree().docinfo
    if docinfo.doctype or docinfo.internalDTD is not None or docinfo.externalDTD is not None:
        raise URDFError(_DTD_MESSAGE.format(path=where))
    return data, prefixes, root


_UNDECLARED = re.compile(r"Namespace prefix \S+ (?:on|for) \S+ is not defined")
_ROOT_TAG = re.compile(rb"<(?![?!])[A-Za-z_][\w.:-]*")
_COMMENT = re.compile(rb"<!--.*?-->", re.S)
_USED_PREFIX = re.compile(
    rb"<\s*/?\s*([A-Za-z_][\w.-]*):[A-Za-z_]|\s([A-Za-z_][\w.-]*):[A-Za-z_][\w.-]*\s*="
)
_DECLARED_PREFIX = re.compile(rb"xmlns:([A-Za-z_][\w.-]*)\s*=")


def _parse_declaring_prefixes(where: str, data: bytes):
    """Parse; if namespace prefixes are undeclared, declare them on the root element and retry."""
    try:
        return data, (), _parse_safely(where, data)
    except URDFError as err:
        if not _UNDECLARED.search(str(err.__cause__ or "")):
            raise
        text = _COMMENT.sub(b"", data)
        used = {(a or b).decode() for a, b in _USED_PREFIX.findall(text)}
        declared = {p.decode() for p in _DECLARED_PREFIX.findall(text)}
        prefixes = sorted(used - declared - {"xml", "xmlns"})
        root = _ROOT_TAG.search(data)
        if not prefixes or root is None:
            raise
        decl = b"".join(f' xmlns:{p}="urn:undeclared:{p}"'.encode() for p in prefixes)
        data = data[: root.end()] + decl + data[root.end() :]
        return data, tuple(prefixes), _parse_safely(where, data)


def prefix_notice(where: str, prefixes: Sequence[str]) -> str:
    """The one warning for undeclared namespace prefixes."""
    return (
        f"{where}: XML namespace prefix(es) {list(prefixes)} used without a declaration "
        "(Gazebo/ROS extensions); their elements are ignored"
    )


_DTD_MESSAGE = (
    "{path}: document type declarations and entities (<!DOCTYPE>, <!ENTITY>) are not allowed in a "
    "URDF; they are refused to rule out entity expansion and external entities"
)


def _parse_safely(path: Path | str, data: bytes):
    """Parse XML with lxml: entities unresolved, no DTD, no network, no huge trees."""
    from lxml import etree

    parser = etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        huge_tree=False,
        load_dtd=False,
        dtd_validation=False,
        remove_comments=True,
        remove_pis=True,
    )
    try:
        return etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        raise URDFError(f"{path}: not well-formed XML: {err}") from err


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
    link_set = set(links)
    types: dict[str, str] = {}
    parent_of: dict[str, str] = {}  # child link -> joint
    parents: set[str] = set()
    mimic: dict[str, str] = {}
    continuous: list[str] = []
    unlimited: list[str] = []
    for joint in root.findall("joint"):
        name = joint.get("name")
        if not name:
            raise URDFError(f'{where}: a <joint> has no name; every joint needs name="..."')
        if name in types:
            raise URDFError(
                f"{where}: joint '{name}' is defined more than once; joint names must be unique"
            )
        jtype = joint.get("type")
        if jtype not in URDF_JOINT_TYPES:
            raise URDFError(
                f"{where}: joint '{name}' has type {jtype!r}; URDF joint types are "
                f"{list(URDF_JOINT_TYPES)}"
            )
        types[name] = jtype
        ends = {}
        for end in ("parent", "child"):
            el = joint.find(end)
            ends[end] = None if el is None else el.get("link")
            if not ends[end]:
                raise URDFError(f"{where}: joint '{name}' has no <{end} link=\"...\"/>")
            if ends[end] not in link_set:
                raise URDFError(
                    f"{where}: joint '{name}' names {end} link '{ends[end]}', which is "
                    f"not a <link> of the file; its links are {links}"
                )
        child = ends["child"]
        if child in parent_of:
            raise URDFError(
                f"{where}: link '{child}' is the child of two joints ('{parent_of[child]}' "
                f"and '{name}'); a URDF is a tree: every link has at most one parent joint"
            )
        if child == ends["parent"]:
            raise URDFError(f"{where}: joint '{name}' connects link '{child}' to itself")
        parent_of[child] = name
        parents.add(ends["parent"])
        if jtype in MOVING_JOINT_TYPES:
            _check_axis(where, name, joint.find("axis"))
            _check_limit(where, name, jtype, joint.find("limit"))
        el = joint.find("mimic")
        if el is not None:
            mimic[name] = el.get("joint") or "?"
        if jtype == "continuous":
            continuous.append(name)
            if _as_revolute(joint):
                unlimited.append(name)
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
    _check_reachable(where, roots[0], links, parent_of, root)
    from lxml import etree

    xml = etree.tostring(root, encoding="unicode")
    leaves = tuple(lk for lk in links if lk not in parents)
    return URDFDescription(
        path, data, xml, types, leaves, mimic, tuple(continuous), tuple(unlimited), prefixes
    )


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
    child_of = {}
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


def __getattr__(name: str):
    """``inspect_text`` and ``urdf_path_of`` moved to :mod:`.inspection` (#11); still importable here."""
    if name in ("inspect_text", "urdf_path_of", "STRUCTURAL_SAMPLES"):
        from . import inspection

        return getattr(inspection, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
