"""Serial arms from Denavit-Hartenberg tables: the table, its URDF, and the arm (docs/MATH.md (D)).

A table lists, per joint, ``a`` [m], ``alpha`` [rad], ``d`` [m], ``theta`` [rad] (the offset of the
joint variable), the joint type (revolute or prismatic), its limits and a link radius for the
visuals. Two conventions:

* ``"standard"`` (distal): ``T_i = Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)``, joint ``i`` turns about
  ``z_{i-1}`` — eq. (H1);
* ``"modified"`` (proximal, Craig): ``T_i = Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i)``, joint ``i``
  turns about ``z_i`` — eq. (H2).

:func:`dh_urdf` writes the URDF (joints ``joint1 … jointN`` along z of their frames, a fixed
``tool`` frame at the end, cylinders between joint origins, uniform-rod inertias); Pinocchio then
does all kinematics. :func:`read_dh` reads the ``--dh FILE`` format (JSON or CSV, see
docs/design.md).

Example:
    >>> from fault_tolerance.model.dh import TEMPLATES, arm_from_dh
    >>> import numpy as np
    >>> arm = arm_from_dh(TEMPLATES["spatial_4r"], task="position")
    >>> q = np.array([0.3, -1.1, 0.7, 0.5])  # shoulder-to-tool distance² = 0.26 + 0.24 cos q4
    >>> arm.n, round(float(np.sum((arm.fk(q) - [0, 0, 0.5]) ** 2)), 12)
    (4, 0.470619814854)
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.formats.registry import format_named
from fault_tolerance.model.formats.urdf import read_urdf
from fault_tolerance.model.loading import arm_from_description

CONVENTIONS = ("standard", "modified")
KINDS = ("revolute", "prismatic")
#: Fields of one joint in a DH file, with their defaults (``None``: required).
JOINT_FIELDS: dict[str, object] = {
    "a": None,
    "alpha": None,
    "d": None,
    "theta": 0.0,
    "type": "revolute",
    "lower": -math.pi,
    "upper": math.pi,
    "velocity": 3.0,
    "effort": 50.0,
    "radius": 0.03,
}
#: Most joints a DH table may have (the toolkit's arms are small; this bounds the work).
MAX_DH_JOINTS = 64
#: Largest |a|, |d| [m] and |θ|, |α| [rad] a table may hold.
MAX_LENGTH = 100.0
MAX_ANGLE = 4 * math.pi
#: Linear density of the links' uniform rods [kg/m] (aluminium tube, ~2 kg per metre).
LINK_DENSITY = 2.0


@dataclass(frozen=True)
class DHJoint:
    """One row of a DH table: lengths [m], angles [rad], limits [rad or m, rad/s or m/s, N·m or N]."""

    a: float
    alpha: float
    d: float
    theta: float = 0.0
    kind: str = "revolute"
    lower: float = -math.pi
    upper: float = math.pi
    velocity: float = 3.0
    effort: float = 50.0
    radius: float = 0.03

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InvalidInput(f"DH joint type {self.kind!r} is not one of {list(KINDS)}")
        for name in ("a", "alpha", "d", "theta", "lower", "upper", "velocity", "effort", "radius"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise InvalidInput(f"DH joint field {name} must be a finite number, got {value!r}")
        if max(abs(self.a), abs(self.d)) > MAX_LENGTH:
            raise InvalidInput(f"DH lengths a, d must be within ±{MAX_LENGTH} m")
        if max(abs(self.alpha), abs(self.theta)) > MAX_ANGLE:
            raise InvalidInput(f"DH angles alpha, theta must be within ±{MAX_ANGLE:.4g} rad")
        if not self.lower < self.upper:
            raise InvalidInput(
                f"DH joint limits need lower < upper, got {self.lower}, {self.upper}"
            )
        if self.velocity <= 0 or self.effort <= 0 or self.radius <= 0:
            raise InvalidInput("DH joint velocity, effort and radius must be > 0")


@dataclass(frozen=True)
class DHTable:
    """A serial arm: its joints, the convention, and the tool offset ``tool_xyz`` [m] after them."""

    joints: tuple[DHJoint, ...]
    convention: str = "standard"
    tool_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "dh_arm"
    notes: Mapping[str, str] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if self.convention not in CONVENTIONS:
            raise InvalidInput(
                f"DH convention {self.convention!r} is not one of {list(CONVENTIONS)}"
            )
        if not 1 <= len(self.joints) <= MAX_DH_JOINTS:
            raise InvalidInput(
                f"a DH table needs 1 to {MAX_DH_JOINTS} joints, got {len(self.joints)}"
            )
        if len(self.tool_xyz) != 3 or not all(math.isfinite(v) for v in self.tool_xyz):
            raise InvalidInput(f"DH tool_xyz must be three finite numbers, got {self.tool_xyz}")
        if not self.name.replace("_", "").isalnum():
            raise InvalidInput(f"DH table name {self.name!r}: letters, digits and _ only")

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.joints)

    @property
    def length(self) -> float:
        """Total length [m]: the sum of every ``|a|``, ``|d|`` and the tool offset's norm."""
        return sum(abs(j.a) + abs(j.d) for j in self.joints) + float(np.linalg.norm(self.tool_xyz))

    def with_joint(self, i: int, **changes: Any) -> DHTable:
        """The table with joint ``i`` (0-based) changed (``a=``, ``d=``, ``lower=``, …)."""
        joints = list(self.joints)
        joints[i] = replace(joints[i], **changes)
        return replace(self, joints=tuple(joints))


# -- transforms --------------------------------------------------------------------------------


def _rot_x(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _rot_z(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _trans(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _joint_origins(table: DHTable) -> list[np.ndarray]:
    """Fixed placements (4x4) before each joint and of the tool, n + 1 of them.

    Standard (H1): joint ``i`` sits at frame ``i-1``; between joints ``i`` and ``i+1`` stands
    ``Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)`` (the joint variable turns or slides along z first, and
    ``Rz``, ``Tz`` commute). Modified (H2): joint ``i`` sits after ``Rx(α_{i-1}) Tx(a_{i-1})
    Rz(θ_i) Tz(d_i)``; the row's own ``a``, ``alpha`` are the ones *before* its joint.
    """
    out = []
    if table.convention == "standard":
        out.append(np.eye(4))
        for j in table.joints:
            out.append(_rot_z(j.theta) @ _trans(0, 0, j.d) @ _trans(j.a, 0, 0) @ _rot_x(j.alpha))
    else:
        for j in table.joints:
            out.append(_rot_x(j.alpha) @ _trans(j.a, 0, 0) @ _rot_z(j.theta) @ _trans(0, 0, j.d))
        out.append(np.eye(4))
    out[-1] = out[-1] @ _trans(*table.tool_xyz)
    return out


def _rpy(R: np.ndarray) -> tuple[float, float, float]:
    """Roll-pitch-yaw of a rotation (URDF's fixed-axis x-y-z), with the pitch = ±π/2 case."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-12:  # gimbal lock: put all of the yaw into the roll
        return math.atan2(-R[1, 2], R[1, 1]), pitch, 0.0
    return math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])


def _origin(T: np.ndarray) -> str:
    x, y, z = (f"{v:.17g}" for v in T[:3, 3])
    r, p, w = (f"{v:.17g}" for v in _rpy(T[:3, :3]))
    return f'<origin xyz="{x} {y} {z}" rpy="{r} {p} {w}"/>'


# -- URDF --------------------------------------------------------------------------------------


def _segment_visual(T_next: np.ndarray, radius: float) -> tuple[str, float]:
    """A cylinder from a link's origin to the next joint's origin, and its length [m]."""
    p = T_next[:3, 3]
    length = float(np.linalg.norm(p))
    if length < 1e-9:
        return f'<visual><geometry><sphere radius="{radius:.6g}"/></geometry></visual>', 0.0
    z = p / length
    x = np.cross([0.0, 0.0, 1.0], z) if abs(z[2]) < 0.999 else np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = p / 2
    geometry = f'<cylinder radius="{radius:.6g}" length="{length:.17g}"/>'
    return f"<visual>{_origin(T)}<geometry>{geometry}</geometry></visual>", length


def _inertial(T_next: np.ndarray, length: float) -> str:
    """A uniform rod along the segment (I = m L²/12 about its centre, m = LINK_DENSITY L)."""
    m = max(LINK_DENSITY * length, 0.1)
    c = T_next[:3, 3] / 2
    i_rod = m * max(length, 0.05) ** 2 / 12
    return (
        f'<inertial><origin xyz="{c[0]:.17g} {c[1]:.17g} {c[2]:.17g}"/><mass value="{m:.6g}"/>'
        f'<inertia ixx="{i_rod:.6g}" ixy="0" ixz="0" iyy="{i_rod:.6g}" iyz="0" izz="{i_rod:.6g}"/>'
        "</inertial>"
    )


def dh_urdf(table: DHTable) -> str:
    """The URDF text of a DH table: ``base_link``, ``link1 … linkN``, a fixed ``tool`` frame."""
    origins = _joint_origins(table)
    parts = [f'<?xml version="1.0"?>\n<robot name="{table.name}">', '<link name="base_link"/>']
    parent = "base_link"
    for i, j in enumerate(table.joints, start=1):
        child = f"link{i}"
        visual, length = _segment_visual(origins[i], j.radius)
        parts.append(
            f'<joint name="joint{i}" type="{j.kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/>{_origin(origins[i - 1])}<axis xyz="0 0 1"/>'
            f'<limit lower="{j.lower:.17g}" upper="{j.upper:.17g}" effort="{j.effort:.6g}" '
            f'velocity="{j.velocity:.6g}"/></joint>'
        )
        parts.append(f'<link name="{child}">{_inertial(origins[i], length)}{visual}</link>')
        parent = child
    parts.append(
        f'<joint name="tool_joint" type="fixed"><parent link="{parent}"/><child link="tool"/>'
        f"{_origin(origins[-1])}</joint>"
    )
    parts.append('<link name="tool"/>\n</robot>\n')
    return "\n".join(parts)


def arm_from_dh(table: DHTable, *, task: str | Sequence[str] = "position"):
    """The :class:`~fault_tolerance.model.arm.Arm` of a DH table (tip ``tool``), via its URDF."""
    desc = read_urdf(Path(f"{table.name}.urdf"), dh_urdf(table).encode("utf-8"))
    return arm_from_description(format_named("urdf"), desc, "tool", task, None, None, None)


# -- the --dh FILE format ---------------------------------------------------------------------


def _joint(row: Mapping[str, object], where: str) -> DHJoint:
    unknown = sorted(set(row) - set(JOINT_FIELDS))
    if unknown:
        raise InvalidInput(f"{where}: unknown DH field(s) {unknown}; allowed: {list(JOINT_FIELDS)}")
    values = {}
    for key, default in JOINT_FIELDS.items():
        value = row.get(key, default)
        if value is None or value == "":
            if default is None:
                raise InvalidInput(f"{where}: DH field '{key}' is missing")
            value = default
        if key != "type":
            try:
                value = float(value)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                raise InvalidInput(
                    f"{where}: DH field '{key}' is not a number: {value!r}"
                ) from None
        values["kind" if key == "type" else key] = value
    return DHJoint(**values)  # type: ignore[arg-type]


def table_from_dict(data: Mapping[str, object], where: str = "DH table") -> DHTable:
    """A table from the JSON form ``{"convention", "joints": [{a, alpha, d, ...}], "tool_xyz"}``."""
    allowed = {"convention", "joints", "tool_xyz", "name"}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise InvalidInput(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
    rows = data.get("joints")
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise InvalidInput(f"{where}: 'joints' must be a list of objects")
    joints = tuple(_joint(r, f"{where}: joint {i + 1}") for i, r in enumerate(rows))
    tool = data.get("tool_xyz", (0.0, 0.0, 0.0))
    if not isinstance(tool, (list, tuple)) or len(tool) != 3:
        raise InvalidInput(f"{where}: 'tool_xyz' must be three numbers [m]")
    return DHTable(
        joints,
        str(data.get("convention", "standard")),
        tuple(float(v) for v in tool),  # type: ignore[arg-type]
        str(data.get("name", "dh_arm")),
    )


#: Largest DH file read [bytes].
MAX_DH_BYTES = 1_000_000


def read_dh(path: str | Path) -> DHTable:
    """Read a ``--dh FILE``: JSON (:func:`table_from_dict`) or CSV.

    A CSV file has a header row of joint fields (``a,alpha,d,theta,type,lower,upper,...``) and
    one row per joint; its convention is standard and it has no tool offset.
    """
    path = Path(path)
    if not path.is_file():
        raise InvalidInput(f"{path}: no such DH file")
    if path.stat().st_size > MAX_DH_BYTES:
        raise InvalidInput(f"{path}: a DH file is at most {MAX_DH_BYTES} bytes")
    text = path.read_text(encoding="utf-8")
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise InvalidInput(f"{path}: not valid JSON ({err.msg}, line {err.lineno})") from None
        if not isinstance(data, dict):
            raise InvalidInput(f"{path}: a JSON DH file holds one object")
        return table_from_dict(data, str(path))
    if path.suffix.lower() == ".csv":
        rows = list(csv.DictReader(io.StringIO(text)))
        joints = tuple(_joint(r, f"{path}: row {i + 2}") for i, r in enumerate(rows))
        return DHTable(joints, name=path.stem.replace("-", "_") or "dh_arm")
    raise InvalidInput(f"{path}: a DH file is .json or .csv")


# -- templates ---------------------------------------------------------------------------------

_HALF_PI = math.pi / 2

#: Start templates: the paper's spatial 4R and a 7-DoF anthropomorphic (S-R-S) arm.
TEMPLATES: dict[str, DHTable] = {
    # The paper's Sec. IV.B values d1 = 0.5, d2 = 0, d3 = 0.4, d4 = 0.1, dt = 0.3 m: a spherical
    # shoulder (joints 1-3), the elbow 0.4 m along the upper arm, the tool 0.1 m along the elbow
    # axis then 0.3 m along the forearm (the shipped robots/spatial_4r.urdf up to joint signs).
    "spatial_4r": DHTable(
        (
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.5),
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.0),
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.4),
            DHJoint(a=0.3, alpha=0.0, d=0.1, theta=_HALF_PI),
        ),
        name="dh_spatial_4r",
    ),
    # An S-R-S arm of the KUKA LBR iiwa 7 class: shoulder 0.34 m up, upper arm and forearm 0.4 m,
    # flange 0.126 m (standard DH, a = 0, alternating ±π/2 twists).
    "anthropomorphic_7r": DHTable(
        (
            DHJoint(a=0.0, alpha=-_HALF_PI, d=0.34, lower=-2.96, upper=2.96),
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.0, lower=-2.09, upper=2.09),
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.4, lower=-2.96, upper=2.96),
            DHJoint(a=0.0, alpha=-_HALF_PI, d=0.0, lower=-2.09, upper=2.09),
            DHJoint(a=0.0, alpha=-_HALF_PI, d=0.4, lower=-2.96, upper=2.96),
            DHJoint(a=0.0, alpha=_HALF_PI, d=0.0, lower=-2.09, upper=2.09),
            DHJoint(a=0.0, alpha=0.0, d=0.126, lower=-3.05, upper=3.05),
        ),
        name="dh_anthropomorphic_7r",
    ),
}
