"""ROS package folders: finding the packages below the folders a user names, and their meshes.

A description names files through ROS packages: ``package://pkg/meshes/a.stl`` and
``$(find pkg)/urdf/...``. Without ROS, the user names folders (``package_dirs``, ``--package-dir
DIR``, repeatable), and a folder ``DIR`` serves package ``pkg`` when, in this order (each rule is
tried on every folder before the next rule):

1. ``DIR/package.xml`` names ``pkg`` (``DIR`` is the package), or ``DIR/pkg`` is a folder, or
   ``DIR`` itself is called ``pkg``;
2. a folder below ``DIR`` holds a ``package.xml`` that names ``pkg`` (a workspace, searched as
   colcon and ament do): folders holding ``COLCON_IGNORE``, ``AMENT_IGNORE`` or ``CATKIN_IGNORE``
   and hidden folders (``.git``) are skipped, a package's own folders are not searched for more
   packages, links are followed only to folders inside ``DIR``, and the walk is bounded
   (:data:`MAX_SEARCH_DEPTH` levels, :data:`MAX_SEARCH_FOLDERS` folders; a package not found in
   a walk cut short says so). A name that two packages below one ``DIR`` carry is an error (as in
   colcon).

:func:`locate_mesh` is the one place where a mesh name becomes a file, for the loader and for
the replay of a saved run alike: ``package://``, ``file://``, absolute and relative names,
normalised (``a//b``, ``./``), and only inside the folders the caller allows (after links are
followed); anything else is :class:`~fault_tolerance.errors.MeshRefused`.

Example:
    >>> import tempfile
    >>> ws = Path(tempfile.mkdtemp())
    >>> pkg = ws / "src" / "robots" / "arm_description"
    >>> pkg.mkdir(parents=True)
    >>> _ = (pkg / "package.xml").write_text("<package><name>arm_description</name></package>")
    >>> find_package("arm_description", [ws]) == pkg.resolve()
    True
"""

from __future__ import annotations

import os
import re
from collections import deque
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

from fault_tolerance.errors import MeshNotFound, MeshRefused, PackageNotFound, URDFError

#: What ``package_dirs`` may be: one folder or several.
PackageDirs = Sequence[str | os.PathLike] | None

#: Deepest folder searched below a named folder (``DIR/a/b/.../pkg``: ``pkg`` at depth 8 is found).
MAX_SEARCH_DEPTH = 8
#: Most folders one search below a named folder visits.
MAX_SEARCH_FOLDERS = 20_000
#: Files that make colcon, ament and catkin skip the folder holding them.
IGNORE_MARKERS = ("COLCON_IGNORE", "AMENT_IGNORE", "CATKIN_IGNORE")


@lru_cache(maxsize=256)
def _package_name(folder: str) -> str | None:
    """The ``<name>`` in ``folder/package.xml``, or None."""
    xml = Path(folder) / "package.xml"
    if not xml.is_file():
        return None
    match = re.search(rb"<name>\s*([^<\s]+)\s*</name>", xml.read_bytes()[:100_000])
    return match.group(1).decode("utf-8", "replace") if match else None


class Workspace(NamedTuple):
    """The packages found below one folder, and why the walk stopped early (empty: it did not)."""

    packages: dict[str, tuple[Path, ...]]  # package name -> its folders (real paths)
    cut_short: str


@lru_cache(maxsize=64)
def packages_below(folder: str) -> Workspace:
    """The ROS packages below ``folder`` (real paths), searched breadth-first as colcon does."""
    top = Path(os.path.realpath(folder))
    found: dict[str, list[Path]] = {}
    seen, queue, visited, cut = {top}, deque([(top, 0)]), 0, ""
    while queue:
        here, depth = queue.popleft()
        visited += 1
        if visited > MAX_SEARCH_FOLDERS:
            cut = f"the search stopped after {MAX_SEARCH_FOLDERS} folders (MAX_SEARCH_FOLDERS)"
            break
        try:
            entries = sorted(os.scandir(here), key=lambda e: e.name)
        except OSError:  # unreadable folder: not searched
            continue
        names = {e.name for e in entries}
        if names.intersection(IGNORE_MARKERS):
            continue
        if "package.xml" in names and (here / "package.xml").is_file():
            name = _package_name(str(here))
            if name:
                found.setdefault(name, []).append(here)
            continue  # colcon does not look for packages inside a package
        for entry in entries:
            sub = _subfolder(entry, top, seen)
            if sub is None:
                continue
            if depth + 1 > MAX_SEARCH_DEPTH:
                cut = f"folders deeper than {MAX_SEARCH_DEPTH} levels were not searched"
                continue
            seen.add(sub)
            queue.append((sub, depth + 1))
    return Workspace({k: tuple(v) for k, v in found.items()}, cut)


def forget_package_search() -> None:
    """Forget the packages found so far (each load starts from what is on disk now)."""
    packages_below.cache_clear()
    _package_name.cache_clear()


def _subfolder(entry: os.DirEntry, top: Path, seen: set[Path]) -> Path | None:
    """The real path of a folder to search: not hidden, not seen, inside ``top`` after links."""
    if entry.name.startswith("."):
        return None
    try:
        if not entry.is_dir(follow_symlinks=True):
            return None
    except OSError:
        return None
    real = Path(os.path.realpath(entry.path))
    if real in seen or not real.is_relative_to(top):
        return None  # a link out of the named folder, or back into it
    return real


def find_package(package: str, package_dirs: PackageDirs, where: str = "") -> Path:
    """The folder of ROS package ``package`` (the rules of the module docstring).

    Raises:
        PackageNotFound: naming the package, the folders searched and a search cut short.
        URDFError: two packages of that name below one folder.
    """
    dirs = [Path(d).expanduser().absolute() for d in (package_dirs or [])]
    for d in dirs:
        if _package_name(str(d)) == package:
            return d
        if (d / package).is_dir():
            return d / package
        if d.name == package and d.is_dir():
            return d
    notes = []
    for d in dirs:
        if not d.is_dir():
            continue
        ws = packages_below(str(d))
        hits = ws.packages.get(package, ())
        if len(hits) > 1:
            raise URDFError(
                f"{where + ': ' if where else ''}package '{package}' is found twice below {d}: "
                f"{[str(h) for h in hits]}; name the one to use with --package-dir "
                "(package_dirs=[...]), or put a COLCON_IGNORE file into the other"
            )
        if hits:
            return hits[0]
        if ws.cut_short:
            notes.append(f"below {d} {ws.cut_short}")
    raise PackageNotFound(package, [str(d) for d in dirs], where, "; ".join(notes))


def locate_mesh(uri: str, roots: Sequence[str | os.PathLike], base: Path | None = None) -> Path:
    """The real path of the mesh file ``uri`` names, which must lie inside one of ``roots``.

    ``package://PKG/REST`` is ``REST`` in the folder of package ``PKG`` (:func:`find_package`
    over ``roots``; no ``..`` in ``REST``); ``file://PATH`` and a plain ``PATH`` are that path,
    relative ones relative to ``base`` (the description's folder), or, without ``base`` (a
    description carried by a saved run), to each root in turn. Empty and ``.`` components are
    dropped (``a//./b`` is ``a/b``). The real path (links followed) must be a file inside a root.

    Raises:
        MeshRefused: the name leads outside ``roots`` (or holds a backslash, a NUL, ``..`` after
            a package name).
        MeshNotFound, PackageNotFound: no such file, or no such package, inside ``roots``.
    """
    real_roots = [Path(os.path.realpath(r)) for r in roots if Path(r).is_dir()]
    if not uri or "\\" in uri or "\x00" in uri:
        raise MeshRefused(uri, "an empty name, a backslash or a NUL is not a mesh file name")
    candidates = _mesh_candidates(uri, roots, base)
    outside = []
    for candidate in candidates:
        real = Path(os.path.realpath(candidate))
        if not any(real.is_relative_to(r) for r in real_roots):
            outside.append(str(real))
        elif real.is_file():
            return real
    if outside and len(outside) == len(candidates):
        raise MeshRefused(
            uri,
            f"leads to {outside[0]}, outside the folders meshes are read from "
            f"{[str(r) for r in real_roots]}; name the folder that holds it with --package-dir "
            "(package_dirs=[...])",
        )
    raise MeshNotFound(uri, f"no such file inside {[str(r) for r in real_roots]}")


def _mesh_candidates(uri: str, roots: Sequence[str | os.PathLike], base: Path | None) -> list[Path]:
    """The paths a mesh name may stand for, in the order they are tried."""
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://") :].partition("/")
        parts = [p for p in rest.split("/") if p not in ("", ".")]
        if not package or not parts:
            raise MeshRefused(uri, "an empty package name or file name after package://")
        if ".." in parts:
            raise MeshRefused(
                uri, "'..' would leave the package; it is not allowed after package://"
            )
        return [find_package(package, roots, f"mesh {uri[:120]!r}").joinpath(*parts)]
    name = uri
    if uri.startswith("file://"):
        name = uri[len("file://") :]
        name = name[len("localhost") :] if name.startswith("localhost/") else name
    path = Path(name)
    if path.is_absolute():
        return [path]
    bases = [base] if base is not None else [Path(r) for r in roots]
    return [Path(b) / path for b in bases]
