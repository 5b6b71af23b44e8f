"""arm: loading (catalog, URDF path, example-robot-data), tasks, input checks and kinematics."""

from __future__ import annotations

import functools
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from conftest import ROOT, SHIPPED

import fault_tolerance as ft
from fault_tolerance.model.arm import TASK_ROWS

H = 1e-6  # central-difference step [rad]
FD_TOL = 1e-5
ATOL = 1e-10


# -- loading --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, n, m",
    [("planar_3r", 3, 2), ("spatial_4r", 4, 3), ("powercube_3r", 3, 2)],
)
def test_catalog_arms_load_with_their_presets(name, n, m):
    """Each catalog name loads with tip 'tool', joints joint1…jointN and its default task."""
    arm = ft.load_arm(name)
    assert arm.name == name
    assert arm.tip == "tool"
    assert (arm.n, arm.m, arm.redundancy) == (n, m, n - m)
    assert arm.joint_names == [f"joint{i}" for i in range(1, n + 1)]
    assert arm.default_lockable == ["joint1", "joint2", "joint3"]


def test_catalog_lists_the_shipped_robots():
    """robots/catalog.json names exactly the three paper arms and the iiwa, each with its URDF."""
    from fault_tolerance.model.catalog import catalog, robot_path

    cat = catalog()
    assert set(cat) == set(SHIPPED) | {"iiwa"}
    for entry in cat.values():
        assert robot_path(entry["urdf"]).is_file()


@pytest.mark.parametrize("as_path", [False, True])
def test_urdf_path_loads_the_same_arm_as_the_catalog(as_path, rng):
    """load_arm('robots/planar_3r.urdf', task='planar') has the catalog arm's joints and J."""
    path = ROOT / "robots" / "planar_3r.urdf"
    arm = ft.load_arm(path if as_path else str(path), task="planar")
    ref = ft.load_arm("planar_3r")
    assert arm.name == "planar_3r"
    assert arm.joint_names == ref.joint_names
    assert arm.tip == "tool"
    q = rng.uniform(-np.pi, np.pi, 3)
    np.testing.assert_allclose(arm.jacobian(q), ref.jacobian(q), atol=ATOL)
    np.testing.assert_allclose(arm.fk(q), ref.fk(q), atol=ATOL)


def test_relative_urdf_path_from_the_repository_root(monkeypatch):
    """A relative URDF path is resolved against the working directory."""
    monkeypatch.chdir(ROOT)
    arm = ft.load_arm("robots/planar_3r.urdf", task="planar")
    assert (arm.n, arm.m) == (3, 2)


def test_panda_has_seven_active_joints_and_fixed_fingers(panda_pose, panda_position):
    """example-robot-data 'panda': 7 active joints, fingers fixed; r = 1 (pose), 4 (position)."""
    for case, m in ((panda_pose, 6), (panda_position, 3)):
        arm = case.arm
        assert arm.joint_names == [f"panda_joint{i}" for i in range(1, 8)]
        assert arm.model.nq == arm.model.nv == 7
        assert not any("finger" in name for name in arm.joint_names)
        assert arm.tip == "panda_hand_tcp"
        assert (arm.m, arm.redundancy) == (m, 7 - m)


def test_panda_default_task_is_pose():
    """load_arm('panda') without a task gives the preset full-pose task."""
    assert ft.load_arm("panda").task == TASK_ROWS


def test_ur5_loads_its_chain_with_a_position_task():
    """example-robot-data 'ur5': the 6 joints to tool0, position task, r = 3."""
    arm = ft.load_arm("ur5")
    assert arm.n == 6
    assert arm.tip == "tool0"
    assert arm.task == ("x", "y", "z")
    assert arm.redundancy == 3
    assert arm.joint_names[0] == "shoulder_pan_joint"
    assert arm.jacobian(arm.neutral()).shape == (3, 6)


@pytest.mark.parametrize(
    "task, rows",
    [
        ("planar", ("x", "y")),
        ("position", ("x", "y", "z")),
        ("pose", TASK_ROWS),
        (["x", "y", "rz"], ("x", "y", "rz")),
        (["rz", "x"], ("x", "rz")),
        ("x,z,ry", ("x", "z", "ry")),
    ],
)
def test_task_rows_select_rows_of_the_pose_jacobian(task, rows, rng):
    """A task selects its rows (in canonical order x y z rx ry rz) of the pose Jacobian and fk."""
    arm = ft.load_arm("spatial_4r", task=task)
    full = ft.load_arm("spatial_4r", task="pose")
    assert arm.task == rows
    idx = [TASK_ROWS.index(r) for r in rows]
    q = rng.uniform(-np.pi, np.pi, 4)
    np.testing.assert_allclose(arm.jacobian(q), full.jacobian(q)[idx], atol=ATOL)
    np.testing.assert_allclose(arm.fk(q), full.fk(q)[idx], atol=ATOL)


@pytest.mark.parametrize("task", ["bogus", "", [], ["x", "q"], ["x", "x"], "x,,y,w"])
def test_bad_task_raises_invalid_task(task):
    """A task that is not planar/position/pose or distinct rows among x y z rx ry rz is refused."""
    with pytest.raises(ft.InvalidTask, match="x"):
        ft.load_arm("planar_3r", task=task)


def test_parse_task_message_lists_the_allowed_tasks():
    """InvalidTask names the allowed tasks and rows."""
    with pytest.raises(ft.InvalidTask) as err:
        ft.parse_task("sideways")
    msg = str(err.value)
    for word in ("planar", "position", "pose", "rz"):
        assert word in msg


def test_unknown_robot_raises_robot_not_found_listing_names():
    """An unknown robot name raises RobotNotFound listing shipped and example-robot-data names."""
    with pytest.raises(ft.RobotNotFound) as err:
        ft.load_arm("no_such_robot_xyz")
    msg = str(err.value)
    assert "no_such_robot_xyz" in msg
    for name in ("planar_3r", "spatial_4r", "powercube_3r", "panda", "ur5"):
        assert name in msg
    assert isinstance(err.value, ft.FaultToleranceError)


def test_missing_urdf_file_raises_urdf_error(tmp_path):
    """A URDF path that does not exist raises URDFError naming the file."""
    with pytest.raises(ft.URDFError, match="missing.urdf"):
        ft.load_arm(tmp_path / "missing.urdf")


@pytest.mark.parametrize("tip", ["no_such_frame", ""])
@pytest.mark.parametrize(
    "robot", ["planar_3r", "spatial_4r", str(ROOT / "robots" / "powercube_3r.urdf"), "panda"]
)
def test_unknown_tip_raises_frame_not_found(robot, tip):
    """An unknown (or empty) tip frame raises FrameNotFound naming it and listing the frames."""
    with pytest.raises(ft.FrameNotFound) as err:
        ft.load_arm(robot, tip=tip)
    assert f"'{tip}'" in str(err.value)
    assert "frames are" in str(err.value)


@pytest.mark.parametrize(
    "q",
    [np.zeros(2), np.zeros(4), np.zeros((3, 1)), [0.0, np.nan, 0.0], [np.inf, 0.0, 0.0]],
    ids=["short", "long", "2d", "nan", "inf"],
)
@pytest.mark.parametrize("method", ["fk", "jacobian", "placement", "jacobian_derivatives"])
def test_bad_configuration_raises_invalid_input(planar_3r, q, method):
    """A configuration of the wrong length or with non-finite entries raises InvalidInput."""
    with pytest.raises(ft.InvalidInput):
        getattr(planar_3r.arm, method)(q)


def test_invalid_input_message_names_the_expected_shape(panda_pose):
    """InvalidInput for a wrong-length q says the shape needed and the joints."""
    with pytest.raises(ft.InvalidInput, match=r"\(7,\)") as err:
        panda_pose.arm.jacobian(np.zeros(9))
    assert "panda_joint1" in str(err.value)


def test_random_q_within_limits(robot, rng):
    """Arm.random_q draws inside the joint limits."""
    arm = robot.arm
    for _ in range(20):
        q = arm.random_q(rng)
        assert np.all(q >= arm.lower) and np.all(q <= arm.upper)


def test_import_does_not_import_meshcat_or_matplotlib():
    """`import fault_tolerance` in a fresh interpreter imports neither meshcat nor matplotlib."""
    code = (
        "import sys, fault_tolerance\n"
        "heavy = sorted(m for m in sys.modules if m.split('.')[0] in ('meshcat', 'matplotlib'))\n"
        "print(heavy)\n"
        "sys.exit(1 if heavy else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


# -- kinematics -----------------------------------------------------------------------------


@functools.cache
def _load_pose_arm(robot: str) -> ft.Arm:
    return ft.load_arm(robot, task="pose")


def _pose_arm(case):
    """The same robot with the full 6-row pose task (to check angular rows as well)."""
    if case.arm.task == TASK_ROWS:
        return case.arm
    return _load_pose_arm("panda" if case.id.startswith("panda") else case.id)


def test_fk_is_tip_translation_and_rotation_vector(robot, rng):
    """fk's linear rows are the tip origin and its angular rows log3 of the tip rotation."""
    arm = _pose_arm(robot)
    q = arm.random_q(rng)
    M = arm.placement(q)
    np.testing.assert_allclose(
        arm.fk(q), np.concatenate([M.translation, pin.log3(M.rotation)]), atol=ATOL
    )


def test_jacobian_linear_rows_match_fk_central_differences(robot, rng, draw_q):
    """Linear rows of J equal central differences of fk (h = 1e-6)."""
    arm = robot.arm
    lin = [k for k, row in enumerate(arm.task) if row in ("x", "y", "z")]
    eye = np.eye(arm.n)
    for _ in range(3):
        q = draw_q(robot, rng)
        fd = np.column_stack(
            [(arm.fk(q + H * eye[j]) - arm.fk(q - H * eye[j])) / (2 * H) for j in range(arm.n)]
        )
        np.testing.assert_allclose(arm.jacobian(q)[lin], fd[lin], atol=FD_TOL)


def test_jacobian_angular_rows_match_rotation_central_differences(robot, rng):
    """Angular rows of J (world axes) equal log3(R(q+h) R(q−h)ᵀ) / 2h."""
    arm = _pose_arm(robot)
    eye = np.eye(arm.n)
    for _ in range(3):
        q = arm.random_q(rng)
        fd = np.column_stack(
            [
                pin.log3(
                    arm.placement(q + H * eye[j]).rotation
                    @ arm.placement(q - H * eye[j]).rotation.T
                )
                / (2 * H)
                for j in range(arm.n)
            ]
        )
        np.testing.assert_allclose(arm.jacobian(q)[3:], fd, atol=FD_TOL)


def test_jacobian_derivatives_match_central_differences(robot, rng):
    """arm.jacobian_derivatives(q)[j] equals (J(q + h e_j) − J(q − h e_j)) / 2h."""
    for arm in (robot.arm, _pose_arm(robot)):
        eye = np.eye(arm.n)
        for _ in range(3):
            q = arm.random_q(rng)
            dJ = arm.jacobian_derivatives(q)
            assert dJ.shape == (arm.n, arm.m, arm.n)
            fd = np.array(
                [
                    (arm.jacobian(q + H * eye[j]) - arm.jacobian(q - H * eye[j])) / (2 * H)
                    for j in range(arm.n)
                ]
            )
            np.testing.assert_allclose(dJ, fd, atol=FD_TOL)


def test_jacobian_unchecked_equals_jacobian(robot, rng):
    """The unchecked Jacobian of the control loop equals the checked one."""
    q = robot.arm.random_q(rng)
    np.testing.assert_allclose(robot.arm.jacobian_unchecked(q), robot.arm.jacobian(q), atol=0)


def test_planar_3r_jacobian_closed_form(planar_3r, rng):
    """The planar 3R with 0.5 m links has the textbook Jacobian −Σ l sin / Σ l cos."""
    q = rng.uniform(-np.pi, np.pi, 3)
    c = np.cumsum(q)
    link = 0.5
    J = np.array(
        [
            [-link * np.sin(c[k:]).sum() for k in range(3)],
            [link * np.cos(c[k:]).sum() for k in range(3)],
        ]
    )
    np.testing.assert_allclose(planar_3r.arm.jacobian(q), J, atol=ATOL)
