"""The arm a run carries: its checked description text, tip, task and joints, rebuilt without the file.

A saved run must replay on another machine without trusting anything in it. So a run stores the
description format (``description_format``: ``urdf`` or ``mjcf``; a xacro file is stored as the
URDF it expands to; a record without it is a URDF) and the text its arm was built from, after that
format's checks, under the format's name (``record["urdf"]``, ``record["mjcf"]``), the tip, the task,
the active joints and the configuration the other joints are fixed at (:func:`arm_record`), and
:func:`arm_from_record` rebuilds the arm from that text alone, checking it again as if it were a
file someone handed us. No path written in the run is ever opened:

* the description is the stored text, never a file named in the run (an MJCF text may include
  no file);
* a mesh is opened only if its name resolves, after following links, to a file *inside* one of
  the package folders the caller names (``--package-dir``, workspaces searched as the loader
  searches them), or inside the installed robot data of a named robot (our ``robots/`` for
  shipped arms, example-robot-data's models for its arms). Names are read exactly as the loader
  reads them, by the same function (:func:`~.formats.packages.locate_mesh`): ``package://``
  (no ``..`` after the package), ``file://`` and absolute paths, relative names (tried against
  each of those folders, since a run carries no folder of its own); a name leading elsewhere is
  :class:`~fault_tolerance.errors.MeshRefused`, its visual is dropped with one warning and the
  arm is drawn without it. An MJCF mesh is opened only as a relative name (no ``..``) inside one
  of those folders.

Example:
    >>> import fault_tolerance as ft
    >>> arm = ft.load_arm("planar_3r")
    >>> again = arm_from_record(arm_record(arm))
    >>> again.joint_names == arm.joint_names
    True
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from fault_tolerance.errors import InvalidInput, URDFError

#: ``format`` of the record a run stores.
ARM_RECORD_FORMAT = 1
KINDS = ("shipped", "example", "file")


class Source(NamedTuple):
    """What an arm was built from, kept by the loaders for :func:`arm_record`."""

    kind: str  # "shipped", "example" or "file"
    data: bytes  # the checked description bytes
    q_full: list[float] | None  # full-model configuration the inactive joints are fixed at
    root_joint: str | None  # "free_flyer" when the model has a floating root (example robots)
    description_format: str = "urdf"  # the registry format the text is rebuilt with


def remember(
    arm, kind: str, data: bytes, q_full=None, root_joint: str | None = None, fmt: str = "urdf"
):
    """Attach the :class:`Source` of ``arm`` (called by the loaders); returns ``arm``."""
    q = None if q_full is None else [float(v) for v in np.asarray(q_full, dtype=float)]
    arm.built_from = Source(kind, bytes(data), q, root_joint, fmt)
    return arm


def remember_example(arm, name: str, full, q_ref):
    """Attach the :class:`Source` of an example-robot-data arm (its URDF text, ``q_ref`` mapped).

    ``q_ref`` is mapped onto the model that text builds (continuous joints are one angle there, a
    (cos, sin) pair in example-robot-data's model). An arm whose URDF cannot be read that way
    carries no record.
    """
    from fault_tolerance.model.chains import joint_kind
    from fault_tolerance.model.formats.build import build_model
    from fault_tolerance.model.formats.urdf import read_urdf

    try:
        desc = read_urdf(_example_urdf(name))
        model = build_model(desc)
        root = None
        if full.njoints > 1 and joint_kind(full.joints[1]) == "floating":
            model, root = _with_free_flyer(desc, model), "free_flyer"
    except (URDFError, InvalidInput, OSError):
        return arm  # replayed with the arm given, or rebuilt by name
    q = None
    if q_ref is not None:
        q = np.zeros(model.nq)
        for j in range(1, model.njoints):
            jid = full.getJointId(model.names[j])
            if jid >= full.njoints:
                return arm
            src, dst = full.joints[jid], model.joints[j]
            value = np.asarray(q_ref)[src.idx_q : src.idx_q + src.nq]
            if src.nq == 2 and dst.nq == 1:  # continuous: (cos, sin) -> angle
                value = np.array([np.arctan2(value[1], value[0])])
            if len(value) != dst.nq:
                return arm
            q[dst.idx_q : dst.idx_q + dst.nq] = value
    return remember(arm, "example", desc.data, q, root)


def arm_record(arm) -> dict | None:
    """The record of ``arm`` a run stores: format and text, tip, task, joints, fixed configuration.

    None for an arm not built by :func:`~.loading.load_arm` (a hand-made Pinocchio model); such a
    run replays only with the arm given (``replay(run, arm)``).
    """
    src = getattr(arm, "built_from", None)
    if src is None:
        return None
    return {
        "format": ARM_RECORD_FORMAT,
        "name": arm.name,
        "kind": src.kind,
        "description_format": src.description_format,
        src.description_format: src.data.decode("utf-8"),
        "tip": arm.tip,
        "task": list(arm.task),
        "joints": list(arm.joint_names),
        "q_full": src.q_full,
        "root_joint": src.root_joint,
    }


def check_record(record, where: str) -> dict:
    """``record`` if it has the fields and types of :func:`arm_record`, else :class:`InvalidInput`."""
    if not isinstance(record, dict):
        raise InvalidInput(f"{where}: the arm record is not an object")
    fmt = _record_format(record, where)
    types = {
        "name": str,
        "kind": str,
        fmt: str,
        "tip": str,
        "task": list,
        "joints": list,
    }
    for key, kind in types.items():
        if not isinstance(record.get(key), kind):
            raise InvalidInput(
                f"{where}: the arm record's {key!r} must be a {kind.__name__}, "
                f"got {type(record.get(key)).__name__}"
            )
    if record.get("format") != ARM_RECORD_FORMAT or record["kind"] not in KINDS:
        raise InvalidInput(
            f"{where}: arm record format {record.get('format')!r}/{record['kind']!r} is not "
            f"{ARM_RECORD_FORMAT}/{KINDS}; it was written by another version"
        )
    if not all(isinstance(v, str) for v in record["task"] + record["joints"]):
        raise InvalidInput(f"{where}: the arm record's task and joints must be lists of names")
    q = record.get("q_full")
    if q is not None and not (
        isinstance(q, list)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in q)
        and np.all(np.isfinite(np.asarray(q, dtype=float)))
    ):
        raise InvalidInput(f"{where}: the arm record's q_full must be a list of finite numbers")
    if record.get("root_joint") not in (None, "free_flyer"):
        raise InvalidInput(f"{where}: the arm record's root_joint must be null or 'free_flyer'")
    if record.get("root_joint") and record["kind"] != "example":
        raise InvalidInput(
            f"{where}: the arm record's root_joint is for example-robot-data arms only"
        )
    return record


def _record_format(record: dict, where: str) -> str:
    """The record's ``description_format`` (``urdf`` when absent: records before MJCF)."""
    from fault_tolerance.model.formats.registry import FORMATS

    fmt = record.get("description_format", "urdf")
    stored = sorted({f.records_as for f in FORMATS})
    if fmt not in stored:
        raise InvalidInput(
            f"{where}: the arm record's description_format {fmt!r} is not one of {stored}"
        )
    return fmt


def arm_from_record(record: dict, package_dirs: Sequence[str | Path] = (), where: str = "run"):
    """Rebuild the arm of a run from its record alone (see the module docstring for meshes).

    Args:
        record: What :func:`arm_record` stored.
        package_dirs: Folders the user names for ``package://`` meshes; meshes elsewhere are not
            opened.
        where: Names the run in messages.

    Raises:
        InvalidInput, DescriptionError: the record or its text is malformed (one line).
    """
    from fault_tolerance.model.arm import Arm
    from fault_tolerance.model.chains import reduce_model
    from fault_tolerance.model.formats.packages import forget_package_search
    from fault_tolerance.model.formats.registry import format_named

    forget_package_search()
    record = check_record(record, where)
    fmt = format_named(_record_format(record, where))
    label = Path(f"{where} ({fmt.label} of {record['name']})")
    desc = fmt.from_text(label, record[fmt.name].encode("utf-8"))
    model = fmt.build_model(desc)
    if record.get("root_joint") == "free_flyer":
        model = _with_free_flyer(desc, model)
    roots = [Path(d) for d in package_dirs] + _installed_roots(record)
    visual, dropped = fmt.confined_visuals(model, desc, roots)
    if dropped:
        warnings.warn(
            f"{where}: {len(dropped)} mesh(es) not opened ({dropped[0]}); meshes are read only "
            "inside the folders named with --package-dir and installed robot data (URDF: "
            "package://, file://, absolute or relative names; MJCF: relative names)",
            stacklevel=2,
        )
    q_full = record.get("q_full")
    if q_full is not None and len(q_full) != model.nq:
        raise InvalidInput(
            f"{where}: the arm record's q_full has {len(q_full)} numbers, the model {model.nq}"
        )
    try:
        reduced, visual = reduce_model(
            model,
            record["tip"],
            record["joints"],
            None if q_full is None else np.asarray(q_full),
            visual_model=visual,
            label=str(label),
        )
    except (RuntimeError, ValueError) as err:  # Pinocchio's own errors
        raise URDFError(f"{label}: cannot rebuild the arm: {err}") from err
    arm = Arm(reduced, record["tip"], record["task"], name=record["name"], visual_model=visual)
    if arm.joint_names != record["joints"]:
        raise InvalidInput(
            f"{where}: the rebuilt arm has joints {arm.joint_names}, the run {record['joints']}"
        )
    return remember(arm, record["kind"], desc.data, q_full, record.get("root_joint"), fmt=fmt.name)


def _with_free_flyer(desc, model):
    import pinocchio as pin

    try:
        return pin.buildModelFromXML(desc.xml, pin.JointModelFreeFlyer())
    except Exception as err:  # noqa: BLE001 - Pinocchio's C++ errors
        raise URDFError(f"{desc.path}: Pinocchio could not build a model from it: {err}") from err


def _installed_roots(record: dict) -> list[Path]:
    """Robot data installed with the toolkit, trusted for named robots' meshes."""
    if record["kind"] == "shipped":
        from fault_tolerance.model.catalog import robot_path

        return [robot_path("catalog.json").parent]
    if record["kind"] == "example":
        try:
            urdf = _example_urdf(record["name"]).resolve()
        except Exception:  # noqa: BLE001 - not installed, or not an example-robot-data name
            return []
        return [p for p in urdf.parents if p.name == "example-robot-data"][:1]
    return []


def _example_urdf(name: str) -> Path:
    """The installed URDF file of an example-robot-data arm (OSError if it is not installed)."""
    try:
        from example_robot_data.robots_loader import ROBOTS, getModelPath
    except ImportError as err:
        raise OSError("example-robot-data is not installed") from err
    if name not in ROBOTS:
        raise OSError(f"{name!r} is not an example-robot-data name")
    loader = ROBOTS[name]
    sub = Path(loader.path) / loader.urdf_subpath / loader.urdf_filename
    return Path(getModelPath(str(sub))) / sub


def arm_of_run(run, package_dirs: Sequence[str | Path] = (), where: str = "the run"):
    """The arm ``run`` was made with, rebuilt from the record it carries (never from a path in it).

    Raises:
        InvalidInput: the run carries no arm (made by hand, or by an older version): pass the arm.
    """
    record = getattr(run, "arm_record", None)
    if record is None:
        raise InvalidInput(
            f"{where} carries no arm (it was built by hand or saved by an older version); pass "
            "the arm it was made with (arm=...) or simulate it again"
        )
    return arm_from_record(record, package_dirs, where=where)
