"""The description formats the toolkit reads, in one ordered registry (:data:`FORMATS`).

A :class:`DescriptionFormat` says how to recognise a file (suffix and root element), how to read
and check it (into a description whose ``data`` is the checked text), how to build the Pinocchio
model and its visual geometry, which tip to choose when none is named, and how a run's arm record
stores it (the format name and the checked text). :func:`format_of` picks the first format that
recognises a file; loading, inspection, the arm record and replay go through here only.

Adding a format is one module (its reader, checks and builders) and one entry in
:data:`FORMATS` (docs/architecture.md, "Adding a description format").

Example:
    >>> from pathlib import Path
    >>> [f.name for f in FORMATS]
    ['urdf', 'xacro', 'mjcf']
    >>> format_named("mjcf").label
    'MJCF'
    >>> is_description_path(Path("ur5e.urdf.xacro")), is_description_path(Path("arm.yaml"))
    (True, False)
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pinocchio as pin

from fault_tolerance.errors import (
    DescriptionError,
    InvalidInput,
    MJCFError,
    UnknownFormat,
    URDFError,
)
from fault_tolerance.model.formats import build as urdf_build
from fault_tolerance.model.formats import mjcf, tree_lines
from fault_tolerance.model.formats import urdf as urdf_mod
from fault_tolerance.model.formats.xacro import is_xacro
from fault_tolerance.model.formats.xml_safety import root_tag_of

#: Bytes of a file's head read to recognise its format (its root element).
HEAD_BYTES = 4096

PackageDirs = Sequence[str | os.PathLike] | None


@dataclass(frozen=True)
class DescriptionFormat:
    """One description format: recognise, read, build, choose a tip, and how runs record it.

    Attributes:
        name: The format's name (``--description`` files, the arm record's ``description_format``).
        label: Its name in messages (``URDF``, ``MJCF``).
        suffixes: File name endings it is tried for (lower case), for messages and ``detect``.
        detect: ``detect(path, head) -> bool``: the file is in this format (``head``: its first
            :data:`HEAD_BYTES` bytes).
        read: ``read(path, package_dirs, xacro_args) -> description``: the checked description;
            its ``data`` is the checked text, its ``leaves`` the candidate tips, its ``mimic`` the
            joints that follow others; notices are warned once.
        from_text: ``from_text(label, data) -> description``: a stored text checked again.
        build_model: ``build_model(description) -> pin.Model``.
        build_visuals: ``build_visuals(model, description, package_dirs)`` -> the visual
            ``pin.GeometryModel`` (meshes not found left out with one warning) or None.
        default_tip: ``default_tip(description) -> str`` when no tip is named.
        confined_visuals: ``confined_visuals(model, description, roots)`` -> the visuals of a
            stored text whose meshes are opened only inside ``roots``, and the names refused.
        tree_lines: ``tree_lines(description, model)`` -> the lines ``inspect`` lists the tree in.
        error: The toolkit error the format raises (:class:`URDFError`, :class:`MJCFError`).
        coupling: What makes a joint follow another in the format (for messages).
        records_as: The format a run's arm record stores the checked text under (xacro: its
            expansion, a URDF).
    """

    name: str
    label: str
    suffixes: tuple[str, ...]
    detect: Callable[[Path, bytes], bool]
    read: Callable[[Path, Any, Mapping[str, str] | None], Any]
    from_text: Callable[[Path, bytes], Any]
    build_model: Callable[[Any], pin.Model]
    build_visuals: Callable[[pin.Model, Any, Any], pin.GeometryModel | None]
    default_tip: Callable[[Any], str]
    confined_visuals: Callable[
        [pin.Model, Any, Sequence[Path]], tuple[pin.GeometryModel | None, list[str]]
    ]
    tree_lines: Callable[[Any, pin.Model], list[str]]
    error: type[DescriptionError] = DescriptionError
    coupling: str = "<mimic>"
    records_as: str = ""

    def __post_init__(self) -> None:
        if not self.name or not self.suffixes:
            raise InvalidInput("a description format needs a name and at least one suffix")
        if not self.records_as:
            object.__setattr__(self, "records_as", self.name)


def _detect_urdf(path: Path, head: bytes) -> bool:
    """``.urdf`` files, ``.xml`` files whose root is not ``<mujoco>``, any file whose root is ``<robot>``."""
    suffix = path.suffix.lower()
    if is_xacro(path):
        return False
    if suffix == ".urdf" or root_tag_of(head) == "robot":
        return True
    return suffix == ".xml" and not mjcf.detect_mjcf(path, head)


def _detect_xacro(path: Path, head: bytes) -> bool:
    return is_xacro(path)


#: The formats, tried in this order by :func:`format_of`.
FORMATS: tuple[DescriptionFormat, ...] = (
    DescriptionFormat(
        name="urdf",
        label="URDF",
        suffixes=(".urdf", ".xml"),
        detect=_detect_urdf,
        read=urdf_build.read_urdf_file,
        from_text=urdf_build.urdf_from_text,
        build_model=urdf_build.build_model,
        build_visuals=urdf_build.build_visuals,
        default_tip=urdf_mod.default_tip,
        confined_visuals=urdf_build.confined_visuals,
        tree_lines=tree_lines.urdf_tree_lines,
        error=URDFError,
    ),
    DescriptionFormat(
        name="xacro",
        label="xacro",
        suffixes=(".xacro", ".urdf.xacro"),
        detect=_detect_xacro,
        read=urdf_build.read_xacro_file,
        from_text=urdf_build.urdf_from_text,
        build_model=urdf_build.build_model,
        build_visuals=urdf_build.build_visuals,
        default_tip=urdf_mod.default_tip,
        confined_visuals=urdf_build.confined_visuals,
        tree_lines=tree_lines.urdf_tree_lines,
        error=URDFError,
        records_as="urdf",
    ),
    DescriptionFormat(
        name="mjcf",
        label="MJCF",
        suffixes=(".xml",),
        detect=mjcf.detect_mjcf,
        read=mjcf.read_mjcf,
        from_text=mjcf.mjcf_from_text,
        build_model=mjcf.build_model,
        build_visuals=mjcf.build_visuals,
        default_tip=mjcf.default_tip,
        confined_visuals=mjcf.confined_visuals,
        tree_lines=tree_lines.model_tree_lines,
        error=MJCFError,
        coupling="<equality><joint>",
    ),
)


def format_names() -> list[str]:
    """The names of the known formats, in registry order."""
    return [f.name for f in FORMATS]


def format_named(name: str) -> DescriptionFormat:
    """The format called ``name``; an unknown name raises :class:`UnknownFormat` listing them."""
    for fmt in FORMATS:
        if fmt.name == name:
            return fmt
    raise UnknownFormat(f"format {name!r}", format_names())


def is_description_path(path: Path) -> bool:
    """True for the file names some format is tried for (``.urdf``, ``.xml``, ``.xacro``, ...)."""
    name = path.name.lower()
    return any(name.endswith(s) for f in FORMATS for s in f.suffixes)


def format_of(path: Path) -> DescriptionFormat:
    """The format of a file: the first of :data:`FORMATS` whose ``detect`` accepts it.

    Raises:
        DescriptionError: (the format's error) no such file, or not a regular file;
            UnknownFormat: no format recognises it.
    """
    path = Path(path)
    head = _head(path)
    for fmt in FORMATS:
        if fmt.detect(path, head):
            return fmt
    raise UnknownFormat(path, format_names())


def _by_name(path: Path) -> DescriptionFormat | None:
    """The format a file name suggests (its head unread), or None."""
    return next((f for f in FORMATS if f.detect(path, b"")), None)


def _head(path: Path) -> bytes:
    """The first bytes of a regular file (a FIFO or device is refused, never read)."""
    fmt = _by_name(path)
    error, label = (fmt.error, fmt.label) if fmt else (DescriptionError, "description")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        raise error(f"{path}: no such {label} file") from None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            raise error(
                f"{path}: not a regular file (a FIFO, device or folder); a {label} description "
                "is a file"
            )
        return f.read(HEAD_BYTES)


def read_description(
    path: Path, package_dirs: PackageDirs = None, xacro_args: Mapping[str, str] | None = None
) -> tuple[DescriptionFormat, Any]:
    """The format of a file and its checked description."""
    fmt = format_of(Path(path))
    return fmt, fmt.read(Path(path), package_dirs, xacro_args)
