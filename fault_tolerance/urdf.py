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
