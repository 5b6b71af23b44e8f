"""XML that is safe to parse: the checks every URDF (or xacro expansion) passes first.

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

The first stop of reading an arm; :mod:`.urdf` then checks the tree. Importable from
:mod:`.urdf` as before.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from fault_tolerance.errors import DescriptionError, URDFError

#: Largest URDF file accepted [bytes]; real robot descriptions are far smaller.
MAX_URDF_BYTES = 20 * 1024 * 1024

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
    data: bytes,
    where: str,
    *,
    require_robot: bool = True,
    root_tag: str = "robot",
    kind: str = "URDF",
    error: type[DescriptionError] = URDFError,
) -> tuple[bytes, tuple[str, ...]]:
    """Safety checks of XML bytes (size, UTF-8, no DTD/entities, well-formed).

    Returns the bytes, with a declaration added for each namespace prefix the text uses but never
    declares (Gazebo/ROS extensions such as ``<gazebo:plugin>``; URDF readers ignore those
    elements), and the prefixes so declared. ``where`` names the source in errors; the root
    element must be ``<root_tag>`` unless ``require_robot`` is false. ``kind`` names the format
    in messages and ``error`` is the error raised (an MJCF file: ``root_tag="mujoco"``,
    ``kind="MJCF file"``, ``error=MJCFError``).
    """
    data, prefixes, root = _checked_bytes(data, where, kind, error)
    if require_robot and root.tag != root_tag:
        raise error(f"{where}: the root element is <{root.tag}>, a {kind} needs <{root_tag}>")
    return data, prefixes


def _checked_bytes(
    data: bytes, where: str, kind: str = "URDF", error: type[DescriptionError] = URDFError
):
    if len(data) > MAX_URDF_BYTES:
        raise error(f"{where}: {len(data)} bytes is larger than the {MAX_URDF_BYTES} bytes allowed")
    if data.startswith(_BOMS) or b"\x00" in data:
        raise error(f"{where}: not UTF-8 text (UTF-16/32 or binary); a {kind} must be UTF-8")
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(
            f"{where}: not UTF-8 text (invalid byte at offset {err.start}); a {kind} must be UTF-8"
        ) from None
    if _DTD.search(data):
        raise error(_DTD_MESSAGE.format(path=where, kind=kind))
    try:
        data, prefixes, root = _parse_declaring_prefixes(where, data)
    except URDFError as err:
        if error is URDFError:
            raise
        raise error(str(err)) from err.__cause__
    docinfo = root.getroottree().docinfo
    if docinfo.doctype or docinfo.internalDTD is not None or docinfo.externalDTD is not None:
        raise error(_DTD_MESSAGE.format(path=where, kind=kind))
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


_HEAD_COMMENT = re.compile(rb"<!--.*?(?:-->|$)", re.S)
_HEAD_ROOT = re.compile(rb"<(?![?!])([A-Za-z_][\w.:-]*)")


def root_tag_of(head: bytes) -> str | None:
    """The name of the first element in the first bytes of an XML file (comments skipped), or None."""
    match = _HEAD_ROOT.search(_HEAD_COMMENT.sub(b"", head))
    return None if match is None else match.group(1).decode("utf-8", "replace")


def prefix_notice(where: str, prefixes: Sequence[str]) -> str:
    """The one warning for undeclared namespace prefixes."""
    return (
        f"{where}: XML namespace prefix(es) {list(prefixes)} used without a declaration "
        "(Gazebo/ROS extensions); their elements are ignored"
    )


_DTD_MESSAGE = (
    "{path}: document type declarations and entities (<!DOCTYPE>, <!ENTITY>) are not allowed in a "
    "{kind}; they are refused to rule out entity expansion and external entities"
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
