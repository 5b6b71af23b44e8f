"""Default starts and refusals on real arm layouts: the Schunk LWA4P, a Stretch-like mobile arm.

A URDF is written here from the LWA4P joint layout (shoulder 0.35 m, forearm 0.305 m, wrist
offset 0.005263 m, limits ±2.947 / ±2.694 rad, as in larics/schunk_lwa4p_ros's exported
schunk_lwa4p.urdf, whose package.xml licence is "TODO"), with and without a tool frame. The
upstream xacro of ipa320/schunk_modular_robotics (tests/data/robots/lwa4p, manifest "lwa4p") has
the same kinematics and is loaded as it is.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
from real_arms import ARMS, cli_args, load

from fault_tolerance.cli import main

_JOINTS = [  # name, rpy, xyz, limit
    ("1", "0 0 0", "0 0 0", 2.947),
    ("2", "1.5708 0 0", "0 0 0", 2.947),
    ("3", "0 3.14159 0", "0 0.350 0", 2.694),
    ("4", "-1.5708 3.14159 0", "0 0 0", 2.947),
    ("5", "1.5708 0 3.14159", "0 0.005263 0.305", 2.947),
    ("6", "-1.5708 0 0", "0 0 0", 2.947),
]
_INERTIA = '<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'


def _urdf(tool: bool) -> str:
    parts = ['<?xml version="1.0"?>', '<robot name="lwa4p">', '<link name="lwa4p_base_link"/>']
    parent = "lwa4p_base_link"
    for name, rpy, xyz, lim in _JOINTS:
        parts.append(f'<link name="lwa4p_link{name}">{_INERTIA}</link>')
        parts.append(
            f'<joint name="lwa4p_joint{name}" type="revolute"><origin rpy="{rpy}" xyz="{xyz}"/>'
            f'<parent link="{parent}"/><child link="lwa4p_link{name}"/><axis xyz="0 0 1"/>'
            f'<limit effort="20" lower="-{lim}" upper="{lim}" velocity="1.26"/></joint>'
        )
        parent = f"lwa4p_link{name}"
    if tool:
        parts.append('<link name="separator_base"/>')
        parts.append(
            '<joint name="lwa4p_separator_joint" type="fixed"><parent link="lwa4p_link6"/>'
            '<child link="separator_base"/><origin rpy="0 0 1.5708" xyz="0 0 0.1"/></joint>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


def _assert_tip_at_wrist_centre(model, tip, seed):
    """Independent Pinocchio check: joints 5, 6 move ``tip`` by < 1e-3 m/rad, joint 4 by > 5 mm/rad."""
    data = model.createData()
    frame = model.getFrameId(tip)
    rng = np.random.default_rng(seed)
    for _ in range(20):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        jac = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED)[:3]
        assert np.linalg.norm(jac[:, 4:], axis=0).max() < 1e-3
        assert np.linalg.norm(jac[:, 3]) > 5e-3  # joint 4 by the 5.263 mm wrist offset


def test_lwa4p_with_a_tool_frame_gets_a_default_start(tmp_path):
    urdf = tmp_path / "lwa4p.urdf"
    urdf.write_text(_urdf(tool=True))
    argv = ["simulate", "--description", str(urdf), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 0


def test_lwa4p_tip_at_the_wrist_centre_is_refused_with_that_cause(tmp_path, capsys):
    """No frame past the wrist: the refusal names the cause, proposes no --tip, and the lockable
    set it proposes (the joints a start there can make up) was tried."""
    urdf = tmp_path / "lwa4p.urdf"
    urdf.write_text(_urdf(tool=False))
    argv = ["simulate", "--description", str(urdf), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "nearly intolerable" in err
    assert "the tip lies at the wrist centre: lwa4p_joint5, lwa4p_joint6 do not move it" in err
    assert "rests on lwa4p_joint1, lwa4p_joint2, lwa4p_joint3, lwa4p_joint4 alone" in err
    assert "no --tip to propose" in err and "--tip " not in err.split("no --tip")[0]
    fix = "--lockable lwa4p_joint4,lwa4p_joint5,lwa4p_joint6"
    assert f"a start passes with {fix}" in err
    fixed = ["simulate", "--description", str(urdf), *fix.split(), "--no-progress"]
    assert main([*fixed, "--out", str(tmp_path / "r")]) == 0
    # Independent check: the tip sits at the wrist centre, so the wrist joints 5, 6 barely move it
    # and the position task rests on joints 1-4 only (no real redundancy left).
    model = pin.buildModelFromXML(_urdf(tool=False))
    _assert_tip_at_wrist_centre(model, "lwa4p_link6", seed=0)


def test_lwa4p_tip_at_the_wrist_centre_gets_a_tried_tip_past_the_wrist(tmp_path, capsys):
    """With a tool frame 0.1 m past the wrist, --tip lwa4p_link6 is refused as a tip at the wrist
    centre and --tip separator_base is proposed; the proposed command runs (exit 0)."""
    urdf = tmp_path / "lwa4p.urdf"
    urdf.write_text(_urdf(tool=True))
    base = ["simulate", "--description", str(urdf), "--no-progress"]
    assert main([*base, "--tip", "lwa4p_link6", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "the tip lies at the wrist centre: lwa4p_joint5, lwa4p_joint6 do not move it" in err
    assert "a start passes with --tip separator_base" in err and "no --tip to propose" not in err
    assert main([*base, "--tip", "separator_base", "--out", str(tmp_path / "r")]) == 0


# -- the upstream LWA4P xacro (tests/data/robots/lwa4p) -------------------------------------


def test_upstream_lwa4p_loads_and_runs_from_its_default_start(tmp_path):
    """The unmodified schunk_description macro through the public loader: the default start of
    the manifest's lockable joints passes, and a short simulate from the command line runs."""
    import fault_tolerance as ft

    arm = load("lwa4p")
    assert arm.joint_names == [f"arm_{i}_joint" for i in range(1, 7)] and arm.tip == "arm_6_link"
    assert np.allclose(arm.upper, [2.947, 2.947, 2.694, 2.947, 2.947, 2.947])
    choice = ft.default_start(arm, ARMS["lwa4p"]["lockable"])
    assert np.linalg.norm(arm.fk(choice.q0) - choice.x0) < 1e-9
    argv = ["simulate", *cli_args("lwa4p"), "--duration", "0.2", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o" / "jvja" / "summary.json").is_file()


def test_upstream_lwa4p_with_every_joint_lockable_is_refused_as_a_tip_at_the_wrist_centre(
    tmp_path, capsys
):
    """Its leaf arm_6_link is the wrist centre and no frame lies past it: the refusal says so and
    proposes the lockable set it tried; pinocchio confirms that joints 5 and 6 do not move it."""
    given = cli_args("lwa4p")
    at = given.index("--lockable")  # the manifest's set, replaced by every joint
    argv = ["simulate", *given[:at], *given[at + 2 :], "--lockable", "all", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "the tip lies at the wrist centre: arm_5_joint, arm_6_joint do not move it" in err
    assert "a start passes with --lockable arm_4_joint,arm_5_joint,arm_6_joint" in err
    assert "no --tip to propose" in err
    _assert_tip_at_wrist_centre(load("lwa4p").model, "arm_6_link", seed=1)


_STRETCH_LIKE = """<?xml version="1.0"?>
<robot name="stretch_like">
  <link name="base_link"/>
  <link name="mast"/><link name="lift"/><link name="l0"/><link name="l1"/><link name="grasp"/>
  <joint name="joint_yaw" type="revolute"><parent link="base_link"/><child link="mast"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="joint_lift" type="prismatic"><parent link="mast"/><child link="lift"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 0 1"/><limit lower="0" upper="1.0" effort="10" velocity="1"/></joint>
  <joint name="joint_arm_l0" type="prismatic"><parent link="lift"/><child link="l0"/>
    <origin xyz="0.1 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.25" effort="10" velocity="1"/></joint>
  <joint name="joint_arm_l1" type="prismatic"><parent link="l0"/><child link="l1"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.25" effort="10" velocity="1"/></joint>
  <joint name="joint_grasp" type="fixed"><parent link="l1"/><child link="grasp"/>
    <origin xyz="0.05 0 0"/></joint>
</robot>
"""


def test_every_structural_joint_is_left_out_by_one_fix(tmp_path, capsys):
    """A Stretch-like arm (base yaw, lift, two telescoping joints; position task): the yaw and
    the lift are each the only joint for their direction, so both are structurally intolerable.
    The refusal proposes --lockable without both (dropping one alone meets the other), and that
    fix runs (exit 0)."""
    import fault_tolerance as ft
    from fault_tolerance.planning.start_checks import intolerable_everywhere

    urdf = tmp_path / "stretch_like.urdf"
    urdf.write_text(_STRETCH_LIKE)
    arm = ft.load_arm(urdf, tip="grasp", task="position")
    singles = [(j,) for j in arm.joint_names]
    assert sorted(intolerable_everywhere(arm, singles)) == [("joint_lift",), ("joint_yaw",)]
    base = ["simulate", "--description", str(urdf), "--tip", "grasp", "--task", "position",
            "--algorithms", "jvja", "--no-progress", "--radius", "0.02", "--omega", "1"]  # fmt: skip
    assert main([*base, "--lockable", "all"]) == 2
    err = capsys.readouterr().err
    assert "--lockable joint_arm_l0,joint_arm_l1" in err and "a start passes with" in err
    assert (
        main([*base, "--lockable", "joint_arm_l0,joint_arm_l1", "--out", str(tmp_path / "r")]) == 0
    )


def test_a_path_too_fast_in_the_default_plane_gets_a_tried_rows_fix(tmp_path, capsys):
    """The Stretch-like arm with telescopes of 1 mm/s: a circle in x, y (the default rows) needs
    them radially, so no start passes and neither half the rate nor half the radius helps; in
    y, z the yaw and the lift move the tool alone. The refusal proposes --rows y,z, and the
    command with that option, as printed, runs (exit 0)."""
    slow = _STRETCH_LIKE.replace('upper="0.25" effort="10" velocity="1"', 'upper="0.25" effort="10" velocity="0.001"')  # fmt: skip
    assert slow.count('velocity="0.001"') == 2
    urdf = tmp_path / "stretch_slow.urdf"
    urdf.write_text(slow)
    base = ["simulate", "--description", str(urdf), "--tip", "grasp", "--task", "position",
            "--algorithms", "jvja", "--no-progress", "--radius", "0.02", "--omega", "1",
            "--lockable", "joint_arm_l0,joint_arm_l1"]  # fmt: skip
    assert main([*base, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "too fast for the velocity limits (joint_arm_l0, joint_arm_l1)" in err
    proposed = re.search(r"a start passes with (.+?) \(that option set so", err).group(1)
    fixes = proposed.split(" or with ")
    assert "--rows y,z" in fixes and not {"--omega 0.5", "--radius 0.01"} & set(fixes)
    fix = next(f for f in fixes if f.startswith("--rows "))  # the option as printed
    assert main([*base, *fix.split(), "--out", str(tmp_path / "r")]) == 0


def test_still_joints_are_the_wrist_joints_and_a_prismatic_one_is_not_called_a_wrist(tmp_path):
    """``still_joints`` finds the joints that do not move the task at the tip: the LWA4P's wrist
    joints 5, 6 for a position task at the wrist centre (none for a pose task, which they
    rotate), and the Stretch-like lift for a task in x, y, worded without a wrist."""
    import fault_tolerance as ft
    from fault_tolerance.planning.start_checks import still_joints, still_joints_text

    assert still_joints(load("lwa4p"))[0] == ("arm_5_joint", "arm_6_joint")
    assert still_joints(load("lwa4p", task="pose"))[0] == ()
    urdf = tmp_path / "stretch_like.urdf"
    urdf.write_text(_STRETCH_LIKE)
    arm = ft.load_arm(urdf, tip="grasp", task="x,y")
    still, lever = still_joints(arm)
    assert still == ("joint_lift",) and lever < 1e-12
    text = still_joints_text(arm, still, lever)
    assert text.startswith("joint_lift does not move the task (") and "wrist" not in text
