"""MuJoCo MJCF descriptions (``.xml`` whose root element is ``<mujoco>``), read through Pinocchio.

Every file the description is made of passes the XML byte checks of :mod:`.xml_safety` (size,
UTF-8, no DTD or entities, well-formed, root ``<mujoco>``). ``<include file="..."/>`` is resolved
here, never by Pinocchio: the included file must be a regular file (no FIFO, device or folder)
inside the description's folder or one of the package folders (after links are followed), at
most :data:`MAX_MJCF_FILES` files of at most :data:`~.xml_safety.MAX_URDF_BYTES` bytes in all,
nested at most :data:`MAX_INCLUDE_DEPTH` deep. The checked text, includes inlined, is what
Pinocchio reads (``pin.buildModelFromMJCF`` from a private temporary file) and what a run's arm
record carries; a stored text may hold no ``<include>`` at all.

Bodies become frames (``BODY``) and sites frames (``OP_FRAME``), so ``tip=`` names either. The
default tip is the end of the serial chain from the root body (the first body with no or several
child bodies), or the first site on it. Meshes are looked up in ``<compiler meshdir>`` (else
``assetdir``) beside the file; visuals whose mesh is missing are left out with one warning, as for
a URDF.

Example:
    >>> from pathlib import Path
    >>> detect_mjcf(Path("arm.xml"), b'<mujoco model="arm">')
    True
    >>> detect_mjcf(Path("arm.xml"), b'<robot name="arm">')
    False
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

import pinocchio as pin

from fault_tolerance.errors import MJCFError
from fault_tolerance.model.formats.urdf import native_reason, native_stderr
from fault_tolerance.model.formats.xml_safety import (
    MAX_URDF_BYTES,
    _parse_safely,
    check_bytes,
    root_tag_of,
)

#: Most files one MJCF description may consist of (the main file and its includes).
MAX_MJCF_FILES = 64
#: Deepest nesting of ``<include>``.
MAX_INCLUDE_DEPTH = 8
#: Most bodies accepted (Pinocchio's parser recurses along the tree, like the URDF reader).
MAX_MJCF_BODIES = 1000


class MJCFDescription(NamedTuple):
    """An MJCF description that passed :func:`read_mjcf`: the text Pinocchio reads, and its tree."""

    path: Path
    data: bytes  # the checked text, includes inlined (what the arm record stores)
    leaves: tuple[str, ...]  # leaf bodies and every site: the candidate tip frames
    mimic: dict[str, str]  # <equality><joint joint1=a joint2=b>: a follows b
    end: str | None  # the default tip (end of the serial chain from the root), if there is one
    mesh_dir: Path | None  # folder of the mesh files (None: a stored text; meshes confined)
    continuous: tuple[str, ...] = ()  # MJCF hinges keep their range: none is read as ±π
    unlimited: tuple[str, ...] = ()


def detect_mjcf(path: Path, head: bytes) -> bool:
    """True for an ``.xml`` file whose first element is ``<mujoco>``."""
    if path.suffix.lower() != ".xml":
        return False
    return root_tag_of(head) == "mujoco"


def read_mjcf(path: Path, package_dirs: Sequence[str] | None = None, xacro_args=None):
    """Check an MJCF file and the files it includes; the text with includes inlined.

    Raises:
        MJCFError: naming the file and the problem (see the module docstring).
    """
    path = Path(path)
    if xacro_args:
        raise MJCFError(
            f"{path}: xacro arguments {sorted(xacro_args)} given for an MJCF file; only xacro "
            "files (.xacro, .urdf.xacro) take them"
        )
    reader = _Includes(path, package_dirs)
    root = reader.load(path, 0)
    return _described(path, root, _mesh_dir(root, path.parent))


def mjcf_from_text(label: Path, data: bytes) -> MJCFDescription:
    """The description of a stored MJCF text (an arm record): checked again, no include allowed."""
    data, _ = _check(data, str(label))
    root = _parse_safely(label, data)
    if root.find(".//include") is not None:
        raise MJCFError(f"{label}: a stored MJCF text may not <include> files")
    return _described(label, root, None)


def _check(data: bytes, where: str) -> tuple[bytes, tuple[str, ...]]:
    return check_bytes(data, where, root_tag="mujoco", kind="MJCF file", error=MJCFError)


class _Includes:
    """Reads the main file and its includes, confined to the allowed folders, within the budget."""

    def __init__(self, main: Path, package_dirs: Sequence[str] | None) -> None:
        self.main = main
        self.folder = Path(os.path.realpath(main.parent))
        self.roots = [self.folder] + [
            Path(os.path.realpath(Path(d).expanduser())) for d in package_dirs or []
        ]
        self.files = 0
        self.bytes = 0

    def load(self, path: Path, depth: int):
        """The checked root element of ``path`` with its own includes expanded."""
        data = self._read(path)
        data, _ = _check(data, str(path))
        root = _parse_safely(path, data)
        for inc in list(root.iter("include")):
            self._expand(inc, depth)
        return root

    def _expand(self, inc, depth: int) -> None:
        name = inc.get("file")
        if not name:
            raise MJCFError(f'{self.main}: an <include> has no file="..."')
        if depth + 1 > MAX_INCLUDE_DEPTH:
            raise MJCFError(
                f"{self.main}: includes nest deeper than {MAX_INCLUDE_DEPTH} levels at {name!r}"
            )
        target = Path(name) if Path(name).is_absolute() else self.folder / name
        sub = self.load(target, depth + 1)
        parent = inc.getparent()
        at = parent.index(inc)
        for k, el in enumerate(list(sub)):
            parent.insert(at + k, el)
        parent.remove(inc)

    def _read(self, path: Path) -> bytes:
        """The bytes of a regular file inside the allowed folders, within the file and byte budget."""
        real = Path(os.path.realpath(path))
        if not any(real.is_relative_to(r) for r in self.roots):
            raise MJCFError(
                f"{self.main}: <include file=...> names {path}, which is outside the "
                f"description's folder {self.folder} and the package folders; includes are "
                "confined to them (--package-dir DIR adds a folder)"
            )
        self.files += 1
        if self.files > MAX_MJCF_FILES:
            raise MJCFError(
                f"{self.main}: more than {MAX_MJCF_FILES} files included; at most "
                f"{MAX_MJCF_FILES} are accepted"
            )
        try:
            fd = os.open(real, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        except OSError as err:
            raise MJCFError(f"{path}: cannot be read ({err.strerror}); no such MJCF file") from None
        with os.fdopen(fd, "rb") as f:
            info = os.fstat(f.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise MJCFError(
                    f"{path}: not a regular file (a FIFO, device or folder); an MJCF file and "
                    "its includes must be regular files"
                )
            left = MAX_URDF_BYTES - self.bytes
            if info.st_size > left:
                raise MJCFError(
                    f"{path}: {info.st_size} bytes would exceed the {MAX_URDF_BYTES} bytes "
                    "allowed for an MJCF description and its includes"
                )
            data = f.read(left + 1)
        if len(data) > left:  # grew after fstat
            raise MJCFError(f"{path}: larger than the {MAX_URDF_BYTES} bytes allowed")
        self.bytes += len(data)
        return data


def _mesh_dir(root, folder: Path) -> Path:
    """The folder mesh files are relative to: ``<compiler meshdir>``, else ``assetdir``."""
    for comp in root.iter("compiler"):
        sub = comp.get("meshdir") or comp.get("assetdir")
        if sub:
            return folder / sub
    return folder


def _described(path: Path, root, mesh_dir: Path | None) -> MJCFDescription:
    """The description of a checked ``<mujoco>`` tree: its text, leaves, mimic joints, end."""
    from lxml import etree

    world = root.find("worldbody")
    bodies = [] if world is None else list(world.iter("body"))
    if len(bodies) > MAX_MJCF_BODIES:
        raise MJCFError(f"{path}: {len(bodies)} bodies; at most {MAX_MJCF_BODIES} are accepted")
    leaves = [b.get("name") for b in bodies if b.find("body") is None and b.get("name")]
    sites = [s.get("name") for s in ([] if world is None else world.iter("site")) if s.get("name")]
    mimic = {
        eq.get("joint1"): eq.get("joint2") or "(a constant)"
        for eq in root.iter("joint")
        if eq.getparent() is not None and eq.getparent().tag == "equality" and eq.get("joint1")
    }
    data = etree.tostring(root, encoding="utf-8")
    return MJCFDescription(
        Path(path), data, tuple(leaves + sites), mimic, _chain_end(world), mesh_dir
    )


def _chain_end(world) -> str | None:
    """The first body from the root with no or several child bodies (or its first site)."""
    if world is None:
        return None
    tops = world.findall("body")
    if len(tops) != 1:
        return None
    body = tops[0]
    while len(body.findall("body")) == 1:
        body = body.find("body")
    site = next((s.get("name") for s in body.findall("site") if s.get("name")), None)
    return site or body.get("name")


def default_tip(desc: MJCFDescription) -> str:
    """The tip frame when none is named (see the module docstring), else an error listing leaves."""
    if desc.end:
        return desc.end
    raise MJCFError(
        f"{desc.path}: no tip frame given and the model has no single serial chain from one root "
        f"body; name the tip frame (tip=..., --tip) among the bodies and sites {list(desc.leaves)}"
    )


@contextlib.contextmanager
def _as_file(data: bytes) -> Iterator[str]:
    """A private temporary copy of checked text (Pinocchio's MJCF reader takes a file name)."""
    with tempfile.TemporaryDirectory(prefix="ft-mjcf-") as tmp:
        file = Path(tmp) / "model.xml"
        file.write_bytes(data)
        yield str(file)


def build_model(desc: MJCFDescription) -> pin.Model:
    """The kinematic model of a checked MJCF description (``pin.buildModelFromMJCF``)."""
    root = _parse_safely(desc.path, desc.data)
    for el in list(root.iter("mesh", "texture", "hfield", "skin")):  # kinematics opens no file
        if el.getparent() is not None and el.getparent().tag == "asset":
            el.getparent().remove(el)
    for geom in list(root.iter("geom")):
        if geom.get("mesh") is not None or geom.get("hfield") is not None:
            geom.getparent().remove(geom)
    from lxml import etree

    failure = None
    with native_stderr() as log, _as_file(etree.tostring(root)) as file:
        try:
            model = pin.buildModelFromMJCF(file)
        except Exception as err:  # Pinocchio raises RuntimeError / ValueError with C++ messages
            failure = err
    if failure is not None:
        reason = native_reason(log) or " ".join(str(failure).split())[:300]
        raise MJCFError(
            f"{desc.path}: Pinocchio could not build a model from it: {reason}"
        ) from failure
    return model


def build_visuals(
    model: pin.Model, desc: MJCFDescription, package_dirs: Sequence[str] | None
) -> pin.GeometryModel | None:
    """Visual geometry; geoms whose mesh is not found are left out with one warning."""
    visual, dropped = confined_visuals(model, desc, [Path(d) for d in package_dirs or []])
    if dropped:
        names = sorted(set(dropped))
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        warnings.warn(
            f"{desc.path}: {len(names)} mesh file(s) not found, their visuals are left out (the "
            f"kinematics does not need them): {shown}",
            stacklevel=3,
        )
    return visual


def confined_visuals(
    model: pin.Model, desc: MJCFDescription, roots: Sequence[Path]
) -> tuple[pin.GeometryModel | None, list[str]]:
    """Visual geometry and the mesh names left out.

    A file's meshes are looked up in its mesh folder; a stored text's (``mesh_dir`` None) only as
    relative names inside ``roots`` (no ``..``, no absolute path; links followed).
    """
    root = _parse_safely(desc.path, desc.data)
    dropped = _place_meshes(root, desc.mesh_dir, roots)
    from lxml import etree

    with native_stderr() as log, _as_file(etree.tostring(root)) as file:
        try:
            visual = pin.buildGeomFromMJCF(model, file, pin.GeometryType.VISUAL)
        except Exception as err:  # coal/assimp raise ValueError with C++ messages
            reason = native_reason(log) or " ".join(str(err).split())[:200]
            return None, [f"(all: the visual geometry could not be built: {reason})"]
    return visual, dropped


def _place_meshes(root, mesh_dir: Path | None, package_dirs) -> list[str]:
    """Mesh file names made absolute; meshes not found removed with the geoms that use them."""
    for comp in root.iter("compiler"):
        for key in ("meshdir", "assetdir", "texturedir"):
            comp.attrib.pop(key, None)
    for el in list(root.iter("texture", "hfield", "skin")):
        el.getparent().remove(el)  # never drawn; their files are not opened
    missing: dict[str, str] = {}
    for mesh in list(root.iter("mesh")):
        if mesh.getparent() is None or mesh.getparent().tag != "asset":
            continue
        file = mesh.get("file") or ""
        name = mesh.get("name") or Path(file).stem
        found = _mesh_file(file, mesh_dir, package_dirs)
        if found is None:
            missing[name] = file or "(no file)"
            mesh.getparent().remove(mesh)
        else:
            mesh.set("file", str(found))
    for geom in list(root.iter("geom")):
        if geom.get("mesh") in missing:
            geom.getparent().remove(geom)
    return list(missing.values())


def _mesh_file(file: str, mesh_dir: Path | None, package_dirs) -> Path | None:
    """The mesh file of a name: beside the description, or (stored text) inside a package folder."""
    if not file:
        return None
    if mesh_dir is not None:
        path = Path(file) if Path(file).is_absolute() else mesh_dir / file
        return path.resolve() if path.is_file() else None
    parts = file.split("/")
    if Path(file).is_absolute() or "\\" in file or any(p in ("", ".", "..") for p in parts):
        return None
    for d in package_dirs or []:
        real = Path(os.path.realpath(d))
        candidate = Path(os.path.realpath(real.joinpath(*parts)))
        if candidate.is_file() and candidate.is_relative_to(real):
            return candidate
    return None
