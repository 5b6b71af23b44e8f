"""Any frame naming loads: links, joints and frames that share names (Baxter's ``left_hand``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import SEED

import fault_tolerance as ft
from fault_tolerance.model.arm_record import arm_from_record, arm_record
from fault_tolerance.model.chains import reduce_model, restore_frame_names, unique_frame_names

DATA = Path(__file__).resolve().parent / "data" / "robots"
#: Baxter as Rethink Robotics publish it (links and fixed joints share names).
BAXTER = DATA / "baxter_rethink" / "baxter_description" / "urdf" / "baxter.urdf"
#: example-robot-data's copy of the same robot, its frames renamed ``*_joint`` / ``*_link``.
BAXTER_ERD = DATA / "baxter" / "baxter.urdf"


def _joint(name, parent, child, kind="revolute", xyz="0 0 0.2", axis="0 1 0"):
    limit = '<limit lower="-2" upper="2" velocity="2" effort="10"/>' if kind != "fixed" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>{limit}</joint>'
    )


def clash_urdf() -> str:
    """Two 3R arms on one base whose names clash the way real descriptions do.

    * the fixed joint ``left_hand`` and its child link ``left_hand`` (Baxter);
    * the moving joint ``right_j3`` and its child link ``right_j3``;
    * the link ``camera`` (on the left arm) and the fixed joint ``camera`` (on the right arm):
      one name, two places.
    """
    links = [
        "base", "left_l1", "left_l2", "left_wrist", "left_hand", "camera",
        "right_l1", "right_l2", "right_j3", "camera_optical",
    ]  # fmt: skip
    joints = [
        _joint("left_j1", "base", "left_l1", xyz="0 0.2 0.3", axis="0 0 1"),
        _joint("left_j2", "left_l1", "left_l2"),
        _joint("left_j3", "left_l2", "left_wrist"),
        _joint("left_hand", "left_wrist", "left_hand", kind="fixed", xyz="0 0 0.1"),
        _joint("camera_mount", "left_l2", "camera", kind="fixed", xyz="0.05 0 0.1"),
        _joint("right_j1", "base", "right_l1", xyz="0 -0.2 0.3", axis="0 0 1"),
        _joint("right_j2", "right_l1", "right_l2"),
        _joint("right_j3", "right_l2", "right_j3"),
        _joint("camera", "right_j3", "camera_optical", kind="fixed", xyz="0 0 0.1"),
    ]
    body = "".join(f'<link name="{lk}"/>' for lk in links) + "".join(joints)
    return f'<?xml version="1.0"?><robot name="clash">{body}</robot>'


@pytest.fixture
def clash(tmp_path) -> Path:
    path = tmp_path / "clash.urdf"
    path.write_text(clash_urdf())
    return path


def _full_model(path: Path) -> pin.Model:
    return pin.buildModelFromXML(path.read_text())


@pytest.mark.parametrize("path", ["clash", "baxter"])
def test_pinocchio_alone_refuses_to_reduce_these_models(path, clash):
    """The failure reported: buildReducedModel on the full model raises "Several frames match"
    (the reason the toolkit renames frames meanwhile; if Pinocchio ever fixes it, this fails)."""
    model = _full_model(clash if path == "clash" else BAXTER)
    keep = "left_j1" if path == "clash" else "left_s0"
    lock = [j for j in range(1, model.njoints) if model.names[j] != keep]
    with pytest.raises(ValueError, match="Several frames match the filter"):
        pin.buildReducedModel(model, lock, pin.neutral(model))


def test_unique_names_are_restored_exactly(clash):
    """unique_frame_names makes every frame name unique; restore_frame_names gives back the
    original names, in order."""
    model = _full_model(clash)
    before = [f.name for f in model.frames]
    assert len(set(before)) < len(before)
    assert unique_frame_names(model) == len(before) - len(set(before))
    names = [f.name for f in model.frames]
    assert len(set(names)) == len(names)
    restore_frame_names(model)
    assert [f.name for f in model.frames] == before


@pytest.mark.parametrize(
    "tip, joints",
    [
        ("left_hand", ["left_j1", "left_j2", "left_j3"]),
        ("camera_optical", ["right_j1", "right_j2", "right_j3"]),
        ("right_j3", ["right_j1", "right_j2", "right_j3"]),
    ],
)
def test_each_arm_of_the_clash_loads_with_the_full_models_kinematics(clash, tip, joints):
    """Each chain loads (no Pinocchio message), keeps every frame name, and its tip placement is
    the full model's at the same joint angles (other joints at zero), to 1e-12."""
    arm = ft.load_arm(clash, tip=tip, task="pose")
    assert arm.joint_names == joints
    assert not any("\x00" in f.name for f in arm.model.frames)
    full = _full_model(clash)
    assert sorted(f.name for f in arm.model.frames) == sorted(f.name for f in full.frames)
    rng = np.random.default_rng(SEED)
    data = full.createData()
    for _ in range(3):
        q = rng.uniform(-1.5, 1.5, arm.n)
        q_full = pin.neutral(full)
        for name, v in zip(joints, q, strict=True):
            q_full[full.joints[full.getJointId(name)].idx_q] = v
        pin.framesForwardKinematics(full, data, q_full)
        body = next(
            i for i, f in enumerate(full.frames) if f.name == tip and f.type == pin.FrameType.BODY
        )
        np.testing.assert_allclose(arm.fk(q)[:3], data.oMf[body].translation, atol=1e-12)


def test_a_tip_name_shared_at_two_places_is_the_link_with_a_warning(clash):
    """``camera`` is a link on the left arm and a fixed joint on the right: the tip is the link
    (a warning names both frames), and the arm is the left chain up to it."""
    with pytest.warns(UserWarning, match="carried by 2 frames at different places"):
        arm = ft.load_arm(clash, tip="camera")
    assert arm.joint_names == ["left_j1", "left_j2"]


def test_the_callers_model_keeps_its_names_when_reduction_fails(clash):
    """reduce_model restores the frame names of the model it was given, even on an error."""
    model = _full_model(clash)
    before = [f.name for f in model.frames]
    reduce_model(model, "left_hand", None)
    assert [f.name for f in model.frames] == before
    with pytest.raises(ft.FaultToleranceError):
        reduce_model(model, "left_hand", ["left_j1", "nope"])
    assert [f.name for f in model.frames] == before


@pytest.mark.parametrize("tip", ["left_hand", "camera_optical"])
def test_the_arm_record_of_a_clash_round_trips(clash, tip):
    """arm_from_record(arm_record(arm)) rebuilds the clashing arm: same joints, kinematics."""
    arm = ft.load_arm(clash, tip=tip, task="pose")
    again = arm_from_record(arm_record(arm))
    assert again.joint_names == arm.joint_names and again.tip == tip
    rng = np.random.default_rng(SEED)
    for _ in range(3):
        q = rng.uniform(-1.5, 1.5, arm.n)
        np.testing.assert_allclose(again.fk(q), arm.fk(q), atol=1e-12)
        np.testing.assert_allclose(again.jacobian(q), arm.jacobian(q), atol=1e-12)


def _baxter(path: Path, tip: str) -> ft.Arm:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshes not copied
        return ft.load_arm(path, tip=tip, task="pose")


@pytest.mark.parametrize("tip, side", [("left_hand", "left"), ("right_hand", "right")])
def test_rethinks_baxter_matches_example_robot_datas_renamed_copy(tip, side):
    """Rethink's baxter.urdf (the file of the report) loads for either hand; its kinematics is
    that of example-robot-data's copy, whose frames were renamed (``*_hand_link``), to 1e-9."""
    arm = _baxter(BAXTER, tip)
    assert arm.joint_names == [f"{side}_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]
    other = _baxter(BAXTER_ERD, f"{tip}_link")
    assert other.joint_names == arm.joint_names
    rng = np.random.default_rng(SEED)
    for _ in range(3):
        q = arm.random_q(rng)
        np.testing.assert_allclose(arm.fk(q), other.fk(q), atol=1e-9)
        np.testing.assert_allclose(arm.jacobian(q), other.jacobian(q), atol=1e-9)


@pytest.mark.parametrize("tip", ["left_hand", "left_gripper", "right_hand"])
def test_the_arm_record_of_rethinks_baxter_round_trips(tip):
    """The record of a Baxter arm rebuilds it: same joints, kinematics (1e-12)."""
    arm = _baxter(BAXTER, tip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshes not copied
        again = arm_from_record(arm_record(arm))
    assert again.joint_names == arm.joint_names and again.tip == tip
    rng = np.random.default_rng(SEED)
    for _ in range(3):
        q = arm.random_q(rng)
        np.testing.assert_allclose(again.fk(q), arm.fk(q), atol=1e-12)
        np.testing.assert_allclose(again.jacobian(q), arm.jacobian(q), atol=1e-12)


def test_the_cli_simulates_rethinks_baxter(tmp_path, capsys):
    """`simulate --urdf baxter.urdf --tip left_hand` runs (exit 0), no Pinocchio text on stderr."""
    from fault_tolerance.cli import main

    rc = main(["simulate", "--urdf", str(BAXTER), "--tip", "left_hand", "--task", "position",
               "--algorithms", "lnva", "--duration", "0.05", "--no-progress",
               "--out", str(tmp_path / "out")])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "Several frames" not in err and "FrameType" not in err
    assert (tmp_path / "out" / "lnva" / "summary.json").is_file()
