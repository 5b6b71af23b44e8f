"""DH tables: the URDF they write, loaded by Pinocchio, equals an independent DH forward kinematics."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from fault_tolerance.errors import InvalidInput
from fault_tolerance.model.dh import (
    TEMPLATES,
    DHJoint,
    DHTable,
    arm_from_dh,
    dh_urdf,
    read_dh,
    table_from_dict,
)


def _dh_standard(a, alpha, d, theta):
    """Eq. (H1) written out entry by entry (Spong's matrix), independent of the package."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def _dh_modified(a, alpha, d, theta):
    """Eq. (H2) written out entry by entry (Craig's matrix)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )


def _fk(table: DHTable, q: np.ndarray) -> np.ndarray:
    """Tool placement (4x4) by the textbook products, prismatic joints adding to d."""
    T = np.eye(4)
    step = _dh_standard if table.convention == "standard" else _dh_modified
    for j, qi in zip(table.joints, q, strict=True):
        theta = j.theta + (qi if j.kind == "revolute" else 0.0)
        d = j.d + (qi if j.kind == "prismatic" else 0.0)
        T = T @ step(j.a, j.alpha, d, theta)
    tool = np.eye(4)
    tool[:3, 3] = table.tool_xyz
    return T @ tool


def _random_table(rng, convention: str, n: int) -> DHTable:
    joints = tuple(
        DHJoint(
            a=float(rng.uniform(-0.5, 0.5)),
            alpha=float(rng.choice([0.0, math.pi / 2, -math.pi / 2, rng.uniform(-3, 3)])),
            d=float(rng.uniform(-0.5, 0.5)),
            theta=float(rng.uniform(-3, 3)),
            kind="prismatic" if rng.random() < 0.25 else "revolute",
            lower=-2.0,
            upper=2.0,
        )
        for _ in range(n)
    )
    return DHTable(joints, convention, tuple(rng.uniform(-0.2, 0.2, 3)), name=f"rand_{convention}")


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_urdf_kinematics_equal_the_dh_products(convention):
    """Random tables (revolute and prismatic, any twist): Pinocchio's tool pose from the written
    URDF equals the DH matrices' product at random q (1e-12)."""
    rng = np.random.default_rng(3)
    for n in (1, 3, 6):
        table = _random_table(rng, convention, n)
        arm = arm_from_dh(table, task="pose")
        assert arm.joint_names == [f"joint{i}" for i in range(1, n + 1)]
        for _ in range(5):
            q = rng.uniform(-1.5, 1.5, n)
            T = _fk(table, q)
            M = arm.placement(q)
            np.testing.assert_allclose(M.translation, T[:3, 3], atol=1e-12)
            np.testing.assert_allclose(M.rotation, T[:3, :3], atol=1e-12)


def test_templates_load_with_their_geometry():
    """The spatial 4R template keeps the paper's property (shoulder-to-tool distance depends on
    q4 alone: ² = 0.26 + 0.24 cos q4) and the 7R one reaches 1.266 m straight up at q = 0."""
    arm = arm_from_dh(TEMPLATES["spatial_4r"])
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = rng.uniform(-3, 3, 4)
        d2 = np.sum((arm.fk(q) - [0, 0, 0.5]) ** 2)
        assert d2 == pytest.approx(0.26 + 0.24 * math.cos(q[3]), abs=1e-12)
    seven = arm_from_dh(TEMPLATES["anthropomorphic_7r"], task="pose")
    assert seven.n == 7 and seven.redundancy == 1
    np.testing.assert_allclose(seven.fk(np.zeros(7))[:3], [0, 0, 1.266], atol=1e-12)
    np.testing.assert_allclose(seven.lower[:2], [-2.96, -2.09])


def test_files_json_and_csv(tmp_path):
    """A JSON and a CSV DH file give the same arm; unknown fields and bad numbers are refused."""
    rows = [
        {"a": 0, "alpha": math.pi / 2, "d": 0.5},
        {"a": 0.4, "alpha": 0, "d": 0, "lower": -1, "upper": 1},
        {"a": 0.3, "alpha": 0, "d": 0, "type": "revolute"},
    ]
    (tmp_path / "arm.json").write_text(json.dumps({"convention": "standard", "joints": rows}))
    header = "a,alpha,d,theta,type,lower,upper\n"
    body = "".join(
        f"{r['a']},{r['alpha']},{r['d']},0,revolute,{r.get('lower', -math.pi)},{r.get('upper', math.pi)}\n"
        for r in rows
    )
    (tmp_path / "arm.csv").write_text(header + body)
    a, b = read_dh(tmp_path / "arm.json"), read_dh(tmp_path / "arm.csv")
    assert a.joints == b.joints
    assert a.joints[1].lower == -1.0
    with pytest.raises(InvalidInput, match="unknown DH field"):
        table_from_dict({"joints": [{"a": 0, "alpha": 0, "d": 0, "length": 1}]})
    with pytest.raises(InvalidInput, match="missing"):
        table_from_dict({"joints": [{"a": 0, "alpha": 0}]})
    with pytest.raises(InvalidInput, match="finite"):
        table_from_dict({"joints": [{"a": float("nan"), "alpha": 0, "d": 0}]})
    with pytest.raises(InvalidInput, match="convention"):
        table_from_dict({"convention": "craig", "joints": rows})
    with pytest.raises(InvalidInput, match="lower < upper"):
        DHJoint(a=0, alpha=0, d=0, lower=1, upper=-1)
    (tmp_path / "arm.txt").write_text("x")
    with pytest.raises(InvalidInput, match=r"\.json or \.csv"):
        read_dh(tmp_path / "arm.txt")


def test_the_urdf_is_a_plain_urdf(tmp_path):
    """The written URDF loads by path like any other (load_arm) and names a tool frame."""
    import fault_tolerance as ft

    path = tmp_path / "arm.urdf"
    path.write_text(dh_urdf(TEMPLATES["anthropomorphic_7r"]))
    arm = ft.load_arm(str(path), tip="tool", task="position")
    assert arm.n == 7 and arm.m == 3
