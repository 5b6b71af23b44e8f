"""Where a description comes from: URDF and xacro files, and the ROS package folders they name.

Real descriptions live in ROS packages: meshes are ``package://pkg/meshes/...`` and xacro files
include ``$(find pkg)/urdf/...``. Both resolve through the package folders the user passes
(``package_dirs`` / ``--package-dir DIR``, repeatable), without ROS, by
:func:`~.packages.find_package`: ``DIR/pkg``, a ``DIR`` whose ``package.xml`` names ``pkg``, or
a package anywhere below ``DIR`` (a workspace).

xacro files (``.xacro``, ``.urdf.xacro``) are expanded with the ``xacro`` package from PyPI,
imported only for them, patched by :mod:`.xacro_eval` for the expansion: ``${...}`` goes through
a whitelist evaluator instead of ``eval``, xacro reads only regular files inside the package
folders and the file's own folder, and the expansion is bounded in time and size. Every file
xacro reads passes the same byte checks as a URDF (size, UTF-8, no DTD or entities), and the
expanded text then goes through :func:`~.urdf.read_urdf` like any URDF. xacro's own errors become :class:`~.errors.URDFError` naming the missing package
or argument; no xacro traceback reaches the user.

Example:
    >>> from pathlib import Path
    >>> is_xacro(Path("ur5e.urdf.xacro")), is_xacro(Path("ur5e.urdf"))
    (True, False)
    >>> parse_xacro_args(["prefix:=left_", "hand:=true"])
    {'prefix': 'left_', 'hand': 'true'}
"""

from __future__ import annotations

import contextlib
import io
import re
import threading
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

from fault_tolerance.errors import (
    FaultToleranceError,
    InvalidInput,
    UnsafeDescription,
    URDFError,
)
from fault_tolerance.model.formats.packages import PackageDirs, find_package

_XACRO_LOCK = threading.Lock()  # xacro keeps its state in module globals


def is_xacro(path: Path) -> bool:
    """True for ``.xacro`` and ``.urdf.xacro`` files."""
    return path.name.lower().endswith(".xacro")


def parse_xacro_args(items: Sequence[str] | None) -> dict[str, str]:
    """``["name:=value", ...]`` (``--xacro-arg``) as a dict; a malformed item raises."""
    out: dict[str, str] = {}
    for item in items or []:
        name, sep, value = item.partition(":=")
        if not sep or not name.strip():
            raise InvalidInput(f"xacro argument {item!r} is not name:=value (e.g. prefix:=left_)")
        out[name.strip()] = value
    return out


# -- xacro ------------------------------------------------------------------------------------


def expand_xacro(
    path: Path, package_dirs: PackageDirs = None, xacro_args: Mapping[str, str] | None = None
) -> tuple[bytes, list[str]]:
    """The URDF text of a xacro file, and the notices xacro printed.

    Expressions go through :mod:`.xacro_eval`'s whitelist evaluator, files are read only inside
    the package folders and the file's own folder, and the expansion is bounded (see
    docs/xacro.md).

    Raises:
        UnsafeDescription: an expression, a read or the size of the expansion is refused.
        URDFError: xacro is not installed, a package or argument is missing, a file it reads is
            refused by the URDF byte checks, or the xacro is malformed.
    """
    try:
        import xacro
        import xacro.substitution_args  # noqa: F401 - patched while expanding
    except ImportError as err:  # pragma: no cover - xacro is a dependency
        raise URDFError(
            f"{path}: reading xacro files needs the 'xacro' package (pip install xacro)"
        ) from err
    from fault_tolerance.model.formats import xacro_eval

    args = {str(k): str(v) for k, v in (xacro_args or {}).items()}
    notices: list[str] = []
    top = path.absolute()
    roots = [str(top.parent), *(str(Path(d).expanduser().absolute()) for d in package_dirs or [])]
    with (
        _XACRO_LOCK,
        _patched(xacro, package_dirs, notices),
        xacro_eval.confined(xacro, top, roots, check_xml=_xml_checker(notices)),
        _quiet() as said,
    ):
        try:
            doc = xacro.process_file(str(top), mappings=args)
            text = doc.toxml()
        except URDFError:
            raise
        except RecursionError:
            raise UnsafeDescription(f"{path}: nested too deeply to expand") from None
        except Exception as err:  # xacro raises many kinds; none may reach the user raw
            raise _xacro_error(path, err, args) from None
        finally:
            xacro.substitution_args_context["arg"] = {}
    if len(text) > xacro_eval.MAX_OUTPUT_CHARS:
        raise UnsafeDescription(
            f"{path}: the expansion is {len(text)} characters, more than the "
            f"{xacro_eval.MAX_OUTPUT_CHARS} allowed (MAX_OUTPUT_CHARS)"
        )
    notices += [s for s in said.getvalue().splitlines() if s.strip()]
    return text.encode("utf-8"), notices


def declared_xacro_args(path: Path) -> list[bytes]:
    """Names of the ``<xacro:arg name=...>`` of a file (for error messages)."""
    with contextlib.suppress(OSError):
        return re.findall(rb'<xacro:arg\s+name="([^"]+)"', path.read_bytes()[:2_000_000])
    return []


def _xacro_error(path: Path, err: Exception, args: Mapping[str, str]) -> URDFError:
    """A one-line :class:`URDFError` for what xacro raised."""
    import xacro

    inner = getattr(err, "exc", None)
    if isinstance(err, xacro.substitution_args.ArgException) or isinstance(
        inner, xacro.substitution_args.ArgException
    ):
        name = str(inner or err).strip("'\"")
        declared = [a.decode() for a in declared_xacro_args(path)]
        return URDFError(
            f"{path}: xacro argument '{name}' is not set and has no default; pass it with "
            f"xacro_args={{'{name}': ...}} (--xacro-arg {name}:=VALUE)"
            + (f"; the file declares {declared}" if declared else "")
            + (f"; given {sorted(args)}" if args else "")
        )
    cause: BaseException | None = err
    for _ in range(20):  # a toolkit error (missing package, refusal) that xacro wrapped
        if cause is None or isinstance(cause, FaultToleranceError):
            break
        cause = getattr(cause, "exc", None)
    if isinstance(cause, FaultToleranceError):
        return cause if isinstance(cause, URDFError) else URDFError(f"{path}: {cause}")
    reason = " ".join(str(err).split()) or type(err).__name__
    return URDFError(f"{path}: xacro could not expand it: {reason}")


@contextlib.contextmanager
def _quiet() -> Iterator[io.StringIO]:
    """Collect what xacro prints (warnings, locations) instead of letting it reach the terminal."""
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(buf):
        yield buf


def _xml_checker(notices: list[str]):
    """The byte checks of every XML file xacro reads; undeclared prefixes become one notice."""
    from fault_tolerance.model.formats.xml_safety import check_bytes, prefix_notice

    def check(data: bytes, where: str) -> bytes:
        data, prefixes = check_bytes(data, where, require_robot=False)
        if prefixes:
            notices.append(prefix_notice(where, prefixes))
        return data

    return check


@contextlib.contextmanager
def _patched(xacro, package_dirs: PackageDirs, notices: list[str]) -> Iterator[None]:
    """Xacro with ``$(find)`` from our package folders and its warnings collected."""
    subst = xacro.substitution_args
    saved = (subst._eval_find, subst._eval_dict["find"], xacro.warning)

    def find(package: str) -> str:
        return str(find_package(package, package_dirs, "xacro $(find)"))

    def warning(*parts, **_):
        notices.append(" ".join(str(p) for p in parts))

    subst._eval_find = find
    subst._eval_dict["find"] = find
    xacro.warning = warning
    try:
        yield
    finally:
        subst._eval_find, subst._eval_dict["find"], xacro.warning = saved
