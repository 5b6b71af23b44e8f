"""Units: errors in [m] and [rad] apart, λ in (rad/s)²; starts in radians, ``--deg``, the start line.

The second half (docs/units.md): ``--deg`` converts the angular joints' entries only, a start
outside the limits or beyond a turn is refused with a degrees hint
(``fault_tolerance.model.joint_limits.check_start``), and every command prints its start.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from real_arms import ARMS, cli_args, load, path_args

import fault_tolerance as ft
from fault_tolerance.cli import main
from fault_tolerance.cli.common import joint_ranges, joint_values, task_values
from fault_tolerance.model.joint_limits import (
    DEGREES_HINT,
    DEGREES_OPTION_HINT,
    TURN_LIMIT,
    angular_columns,
    check_start,
    degrees_to_radians,
)
from fault_tolerance.model.task_errors import error_norms
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.run import Run
from fault_tolerance.simulation.simulate import simulate


@pytest.fixture(scope="module")
def pose_run():
    """A short Panda pose-task run with a 1 mrad rotation offset at the start."""
    arm = ft.load_arm("panda")
    q0 = arm.q_reference + 0.2
    x0 = arm.fk(q0)
    x0[3:] = (ft.load_arm("panda").fk(q0 + 1e-3))[3:]  # the desired orientation is a bit off
    path = CirclePath(x0, 0.02, 2 * np.pi, 0.05, rows=(0, 1))
    return arm, simulate(arm, path, "lnva", q0=q0, lockable=["panda_joint1"], feedback_gain=5.0)


def test_pose_run_keeps_position_and_orientation_errors_apart(pose_run):
    """error is the position part [m]; orientation_error the rotation angle [rad]; never added."""
    arm, run = pose_run
    lin = [i for i, r in enumerate(arm.task) if r in ("x", "y", "z")]
    np.testing.assert_allclose(
        run.error, np.linalg.norm(run.x[:, lin] - run.x_des[:, lin], axis=1), atol=1e-12
    )
    err0 = arm.task_error(run.x_des[0], run.q[0])
    np.testing.assert_allclose(run.orientation_error[0], np.linalg.norm(err0[3:]), atol=1e-12)
    assert run.orientation_error[0] > 1e-4  # the offset shows up in radians, not in metres
    s = run.summary()
    assert s["tracking_error_max"] == pytest.approx(run.error.max())
    assert s["orientation_error_max"] == pytest.approx(run.orientation_error.max())


def test_orientation_error_survives_save_load_and_csv(pose_run, tmp_path):
    """The orientation error is saved, loaded back and written as its own CSV column."""
    _, run = pose_run
    run.save(tmp_path / "r")
    back = Run.load(tmp_path / "r")
    np.testing.assert_array_equal(back.orientation_error, run.orientation_error)
    header = (tmp_path / "r" / "run.csv").read_text().splitlines()[0].split(",")
    assert header[header.index("error") + 1] == "orientation_error"


def test_planar_run_has_no_orientation_error():
    """Planar and position tasks have only the position error (summary keys unchanged)."""
    arm = ft.load_arm("planar_3r")
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.02)
    q0 = initial_posture(arm, path.x0).q
    run = simulate(arm, path, "lnva", q0=q0)
    assert run.orientation_error is None and "orientation_error_max" not in run.summary()


def test_error_norms_never_add_metres_and_radians():
    """A 5 mm position error and a 0.1 rad rotation stay 5 mm and 0.1 rad."""
    pos, ori = error_norms(("x", "y", "rz"), np.array([[0.003, 0.004, 0.1]]))
    np.testing.assert_allclose(pos, [0.005])
    np.testing.assert_allclose(ori, [0.1])


def test_lock_plot_has_an_orientation_panel_for_pose_tasks(pose_run):
    """plot_lock draws the orientation error [mrad] in a panel of its own for pose tasks."""
    from fault_tolerance.figures import runs as plots

    _, run = pose_run
    fig = plots.plot_lock({"run": run})
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert any("[mm]" in t for t in labels) and any("[mrad]" in t for t in labels)


def test_report_tables_give_lambda_in_its_unit():
    """REPORT.md's λ and δ table headers carry (rad/s)²."""
    from fault_tolerance.paper.report import write_report

    algs = {a: {"jvj_mean": 1.0, "jvj_max": 2.0, "rcn_mean": 3.0, "rcn_max": 4.0} for a in
            ("lnva", "jvja", "mda")}  # fmt: skip
    text = write_report({"cases": {"fig2": {"algorithms": algs}}})
    header = next(line for line in text.splitlines() if line.startswith("| case | λ mean"))
    assert header.count("[(rad/s)²]") == 6


# -- starts in radians, --deg ---------------------------------------------------------------

#: A planar arm on a slider: prismatic x [m], two revolute joints, one continuous joint.
SLIDE_URDF = """<?xml version="1.0"?>
<robot name="slide_3r">
  <link name="base"/>
  {links}
  <link name="tool"/>
  <joint name="slider" type="prismatic"><parent link="base"/><child link="cart"/>
    <axis xyz="1 0 0"/><limit lower="-0.5" upper="0.5" effort="100" velocity="1"/></joint>
  <joint name="joint1" type="revolute"><parent link="cart"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3.14159" upper="3.14159" effort="50" velocity="3"/></joint>
  <joint name="joint2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="50" velocity="3"/></joint>
  <joint name="joint3" type="continuous"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/><limit effort="50" velocity="3"/></joint>
  <joint name="fix" type="fixed"><parent link="l3"/><child link="tool"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>
"""
LINK = (
    '<link name="{}"><inertial><origin xyz="0.25 0 0"/><mass value="1"/><inertia ixx="0.01" '
    'iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>'
)
SHORT = ["--duration", "0.2", "--no-progress"]


@pytest.fixture(scope="module")
def slide(tmp_path_factory):
    """The slider arm's URDF file."""
    path = tmp_path_factory.mktemp("slide") / "slide.urdf"
    links = "\n  ".join(LINK.format(n) for n in ("cart", "l1", "l2", "l3"))
    path.write_text(SLIDE_URDF.format(links=links), encoding="utf-8")
    return path


def slide_args(path) -> list[str]:
    return ["--urdf", str(path), "--tip", "tool", "--task", "planar", "--lockable", "joint2"]


def run_cli(argv, capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def start_lines(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith("start: q0 = ")]


# -- the issue's example ----------------------------------------------------------------------


def test_the_issue_example_is_refused_with_the_degrees_hint():
    """`simulate --robot planar_3r --q0=0,90,45`: exit 2, one line naming joints, values, limits, hint."""
    p = subprocess.run(
        [sys.executable, "-m", "fault_tolerance", "simulate", "--robot", "planar_3r",
         "--q0=0,90,45", "--no-progress"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert p.returncode == 2, p.stderr
    assert p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    line = lines[0]
    assert "joint2 = 90 rad" in line and "joint3 = 45 rad" in line
    assert "limits [-3.142, 3.142] rad" in line
    assert "looks like degrees: pass --deg" in line
    assert "Traceback" not in p.stderr


def test_no_limits_still_refuses_a_value_beyond_a_turn(capsys):
    """With --no-limits a start beyond 2π·1.01 on a revolute joint is still refused with the hint."""
    code, out, err = run_cli(
        ["simulate", "--robot", "planar_3r", "--q0=0,90,45", "--no-limits", *SHORT], capsys
    )
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and DEGREES_HINT in err


def test_deg_gives_the_same_run_as_radians(tmp_path, capsys):
    """`--q0=0,90,45 --deg` runs exactly as the same start in radians: summary.json and start line."""
    rad = ",".join(repr(float(v)) for v in np.deg2rad([0.0, 90.0, 45.0]))
    common = ["simulate", "--robot", "planar_3r", "--algorithms", "jvja", *SHORT]
    code_d, out_d, _ = run_cli([*common, "--q0=0,90,45", "--deg", "--out", str(tmp_path / "d")],
                               capsys)  # fmt: skip
    code_r, out_r, _ = run_cli([*common, f"--q0={rad}", "--out", str(tmp_path / "r")], capsys)
    assert code_d == 0 and code_r == 0
    (line_d,), (line_r,) = start_lines(out_d), start_lines(out_r)
    assert line_d.startswith("start: q0 = [0.0, 1.5708, 0.7854] rad = [0.0, 90.0, 45.0] deg")
    assert line_r == "start: q0 = [0.0, 1.5708, 0.7854] rad (given by --q0)"
    assert "start: every method from the same q0 = [0.0, 1.5708, 0.7854] rad" in out_d
    s_d = json.loads((tmp_path / "d" / "jvja" / "summary.json").read_text())["summary"]
    s_r = json.loads((tmp_path / "r" / "jvja" / "summary.json").read_text())["summary"]
    for key in ("jvj_mean", "jvj_max", "rcn_mean", "rcn_max", "tracking_error_max"):
        assert s_d[key] == pytest.approx(s_r[key], rel=1e-12, abs=1e-15), key
    q_d = np.load(tmp_path / "d" / "jvja" / "run.npz")["q"]
    q_r = np.load(tmp_path / "r" / "jvja" / "run.npz")["q"]
    np.testing.assert_allclose(q_d, q_r, atol=1e-12)


# -- prismatic joints stay metres ------------------------------------------------------------


def test_deg_leaves_prismatic_entries_in_metres(slide, tmp_path, capsys):
    """--deg converts the revolute and continuous entries only; the slider's 0.2 stays 0.2 m."""
    code, out, err = run_cli(
        ["simulate", *slide_args(slide), "--q0", "0.2,0,90,45", "--deg", "--algorithms", "jvja",
         *SHORT, "--out", str(tmp_path / "s")], capsys,
    )  # fmt: skip
    assert code == 0, err
    (line,) = start_lines(out)
    assert line.startswith("start: q0 = [0.2, 0.0, 1.5708, 0.7854] rad = [0.2, 0.0, 90.0, 45.0]")
    assert "(slider in m)" in line
    q = np.load(tmp_path / "s" / "jvja" / "run.npz")["q"]
    np.testing.assert_allclose(q[0], [0.2, 0.0, np.pi / 2, np.pi / 4], atol=1e-12)


def test_angular_columns_and_conversion_of_a_mixed_arm(slide):
    """The slider is the only length; degrees_to_radians converts rows of the others only."""
    arm = ft.load_arm(str(slide), tip="tool", task="planar")
    assert angular_columns(arm).tolist() == [False, True, True, True]
    np.testing.assert_allclose(
        degrees_to_radians(arm, [0.3, 180.0, -90.0, 360.0]), [0.3, np.pi, -np.pi / 2, 2 * np.pi]
    )
    lim = joint_ranges("-0.2:0.4,-90:90,-60:60,-180:180", "--limits", arm, deg=True)
    np.testing.assert_allclose(lim[0], [-0.2, 0.4])
    np.testing.assert_allclose(lim[1:], np.deg2rad([[-90, 90], [-60, 60], [-180, 180]]))
    np.testing.assert_allclose(joint_values("0.1,1,2,3", "--q0", arm), [0.1, 1, 2, 3])
    with pytest.raises(ft.InvalidInput, match=r"--q0 has shape \(3,\); slide needs shape \(4,\)"):
        joint_values("1,2,3", "--q0", arm, deg=True)


def test_a_slider_outside_its_limits_is_refused_without_a_degrees_hint(slide, capsys):
    """A prismatic entry outside its limits is named in metres; no degrees hint for a length."""
    code, out, err = run_cli(
        ["simulate", *slide_args(slide), "--q0", "0.7,0,1.5,1", *SHORT], capsys
    )
    assert code == 2 and out == ""
    assert "slider = 0.7 m (limits [-0.5, 0.5] m)" in err and "degrees" not in err


def test_a_continuous_joint_far_beyond_a_turn_is_refused(slide, capsys):
    """A continuous joint has no position limit to check, but 400 rad is refused as degrees."""
    code, _, err = run_cli(
        ["simulate", *slide_args(slide), "--q0", "0.2,0,1.5,400", "--no-limits", *SHORT], capsys
    )
    assert code == 2 and "joint3 = 400 rad" in err and DEGREES_HINT in err


def test_workspace_deg_converts_only_the_angular_limits(slide):
    """The Python API's deg=True of the workspace limits leaves the slider's metres alone."""
    from fault_tolerance.analysis.workspace.closed_form import parse_limits

    arm = ft.load_arm(str(slide), tip="tool", task="planar")
    lim = parse_limits(arm, "-0.2:0.4,-90:90,-60:60,-180:180", deg=True)
    np.testing.assert_allclose(lim[0], [-0.2, 0.4])
    np.testing.assert_allclose(lim[1, 1], np.pi / 2)


def test_x0_orientation_rows_are_converted_by_deg():
    """--deg converts the rx, ry, rz rows of --x0, never the positions [m]."""
    arm = ft.load_arm("spatial_4r", task="pose")
    x = task_values("0.1,0.2,0.3,90,0,-45", "--x0", arm, deg=True)
    np.testing.assert_allclose(x, [0.1, 0.2, 0.3, np.pi / 2, 0.0, -np.pi / 4])
    np.testing.assert_allclose(
        task_values("0.1,0.2,0.3,1,0,0", "--x0", arm), [0.1, 0.2, 0.3, 1, 0, 0]
    )


# -- the start is always printed --------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, origin",
    [
        (["simulate", "--robot", "planar_3r", "--q0=0.3,1.2,1.0", "--algorithms", "jvja"],
         "(given by --q0)"),
        (["simulate", "--robot", "planar_3r", "--x0", "0.35,0", "--algorithms", "jvja"],
         "(the minimum-RCN posture at --x0)"),
        (["simulate", "--robot", "planar_3r", "--algorithms", "jvja"],
         "(the default start, chosen: see the next line)"),
        (["lock", "--robot", "planar_3r", "--joint", "joint2", "--q0=0.3,1.2,1.0"],
         "(given by --q0)"),
        (["lock", "--robot", "planar_3r", "--joint", "joint2", "--q0=17.19,68.75,57.3", "--deg"],
         "(given by --q0, in degrees)"),
    ],
)  # fmt: skip
def test_every_command_prints_its_start(argv, origin, capsys):
    """simulate and lock print `start: q0 = [...] rad (origin)` whether the start is given or chosen."""
    code, out, err = run_cli([*argv, *SHORT], capsys)
    assert code == 0, err
    (line,) = start_lines(out)
    assert line.endswith(origin)
    q = np.array(json.loads(line.split("q0 = ")[1].split(" rad")[0]))
    assert q.shape == (3,) and np.all(np.abs(q) <= np.pi)
    if "--deg" in argv:
        assert " deg (" in line
        np.testing.assert_allclose(q, np.deg2rad([17.19, 68.75, 57.3]), atol=1e-4)


def test_reproduce_prints_each_case_start(monkeypatch, tmp_path, capsys):
    """reproduce prints one start line per case, from its summary."""
    import fault_tolerance.paper.reproduce as rep

    fake = {"cases": {"fig2": {"robot": "planar_3r", "q0": [0.1, 0.2, 0.3]}},
            "meta": {"seconds": 0.0}}  # fmt: skip
    monkeypatch.setattr(rep, "reproduce", lambda *a, **k: fake)
    code, out, _ = run_cli(["reproduce", "--out", str(tmp_path / "r"), "--no-progress"], capsys)
    assert code == 0
    assert "start: q0 = [0.1, 0.2, 0.3] rad (fig2, planar_3r)" in out


def test_help_says_what_deg_converts(capsys):
    """Every command with angle options documents --deg: which options, and prismatic in metres."""
    for command, options in (
        ("simulate", "--q0"),
        ("lock", "--q0"),
        ("workspace", "--limits"),
        ("design", "the angles of --params"),
    ):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "--deg" in text and f"read {options}" in text, command
        assert "prismatic joints are metres and are not converted" in text, command


# -- the Python API ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def panda():
    return ft.load_arm("panda", task="position")


PANDA_Q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8])


def _panda_path(arm, q0):
    return ft.CirclePath(arm.fk(q0), 0.02, 2 * np.pi, 0.01)


def test_python_simulate_refuses_a_start_in_degrees(panda):
    """ft.simulate: panda_joint4 = -5 is outside [-3.07, -0.07] rad and inside once read as degrees."""
    q = PANDA_Q.copy()
    q[3] = -5.0
    with pytest.raises(ft.InvalidInput) as err:
        ft.simulate(panda, _panda_path(panda, PANDA_Q), "jvja", q0=q, engine="reference")
    text = str(err.value)
    assert (
        "outside the joint limits" in text
        and "panda_joint4 = -5 rad (limits [-3.072, -0.0698]" in text
    )
    assert DEGREES_HINT in text


def test_python_refusal_without_hint_when_it_is_not_degrees(panda):
    """0.5 rad on panda_joint4 is outside its limits, and 0.5° would be too: no degrees hint."""
    q = PANDA_Q.copy()
    q[3] = 0.5
    with pytest.raises(ft.InvalidInput, match="panda_joint4 = 0.5 rad") as err:
        check_start(panda, q)
    assert "degrees" not in str(err.value)


def test_python_limits_off_allows_outside_but_not_beyond_a_turn(panda):
    """limits=False: a start outside the limits runs (the paper's formulation); 400 rad does not."""
    q = PANDA_Q.copy()
    q[3] = 0.5
    run = ft.simulate(panda, _panda_path(panda, q), "jvja", q0=q, limits=False, engine="reference")
    np.testing.assert_allclose(run.q[0], q, atol=1e-12)
    q[3] = 400.0
    assert abs(q[3]) > TURN_LIMIT
    with pytest.raises(ft.InvalidInput, match="beyond a turn.*panda_joint4 = 400 rad") as err:
        ft.simulate(panda, _panda_path(panda, PANDA_Q), "jvja", q0=q, limits=False,
                    engine="reference")  # fmt: skip
    assert DEGREES_HINT in str(err.value)


# -- a real arm from the test data -------------------------------------------------------------


def test_ur5e_start_in_degrees_refused_and_deg_runs_it(capsys):
    """UR5e (tests/data): its manifest start in degrees is refused with the hint; --deg runs it."""
    q_rad = np.array(ARMS["ur5e"]["q0"], dtype=float)
    q_deg = ",".join(f"{v:.6f}" for v in np.rad2deg(q_rad))
    base = ["simulate", *cli_args("ur5e"), *path_args("ur5e"), "--algorithms", "jvja", *SHORT]
    code, out, err = run_cli([*base, f"--q0={q_deg}"], capsys)
    assert code == 2 and out == "" and DEGREES_HINT in err, err
    errors = [ln for ln in err.splitlines() if "error:" in ln]  # (and the missing-mesh warning)
    assert len(errors) == 1 and "shoulder_lift_joint = " in errors[0]
    code, out, err = run_cli([*base, f"--q0={q_deg}", "--deg"], capsys)
    assert code == 0, err
    (line,) = start_lines(out)
    q = np.array(json.loads(line.split("q0 = ")[1].split(" rad")[0]))
    np.testing.assert_allclose(q, np.round(q_rad, 4), atol=1e-4)
    assert load("ur5e").n == len(q)


# -- design --vary dh: the angles of --params ----------------------------------------------------


def test_dh_params_in_degrees_convert_angles_not_lengths_nor_prismatic_limits():
    """theta, alpha and a revolute joint's limits are converted; a, d and a slider's limits not."""
    from fault_tolerance.analysis.design.dh import parse_params
    from fault_tolerance.cli.common import dh_params_from_degrees
    from fault_tolerance.model.dh import DHJoint, DHTable

    table = DHTable(
        joints=(
            DHJoint(a=0.0, alpha=0.0, d=0.2, kind="prismatic", lower=0.0, upper=0.5),
            DHJoint(a=0.3, alpha=0.0, d=0.0),
        )
    )
    text = "upper1:0.3:0.5,d1:0.1:0.2,alpha2:{0|90|-90},theta2:-45:45,upper2:30:170,a2:0.2:0.4"
    got = {p.name: p for p in dh_params_from_degrees(parse_params(text), table, text)}
    assert (got["upper1"].lo, got["upper1"].hi) == (0.3, 0.5)  # the slider's limit [m]
    assert (got["d1"].lo, got["a2"].hi) == (0.1, 0.4)  # lengths [m]
    np.testing.assert_allclose(got["alpha2"].choices, [0.0, np.pi / 2, -np.pi / 2])
    np.testing.assert_allclose([got["theta2"].lo, got["theta2"].hi], [-np.pi / 4, np.pi / 4])
    np.testing.assert_allclose([got["upper2"].lo, got["upper2"].hi], np.deg2rad([30, 170]))
    with pytest.raises(ft.InvalidInput, match="not as multiples of pi"):
        dh_params_from_degrees(parse_params("alpha2:{0|pi/2}"), table, "alpha2:{0|pi/2}")


@pytest.mark.slow
def test_design_dh_with_deg_is_the_radian_design(tmp_path, capsys):
    """`design --vary dh --params alpha2:{0|90} --deg` gives the design of alpha2:{0|π/2}."""
    common = ["design", "--vary", "dh", "--popsize", "4", "--generations", "0", "--rounds", "0",
              "--workers", "0", "--no-progress"]  # fmt: skip
    deg = [*common, "--params", "d3:0.2:0.6,alpha2:{0|90}", "--deg", "--out", str(tmp_path / "d")]
    rad = [
        *common,
        "--params",
        f"d3:0.2:0.6,alpha2:{{0|{np.pi / 2!r}}}",
        "--out",
        str(tmp_path / "r"),
    ]
    assert run_cli(deg, capsys)[0] == 0
    assert run_cli(rad, capsys)[0] == 0
    d = json.loads((tmp_path / "d" / "design.json").read_text())
    r = json.loads((tmp_path / "r" / "design.json").read_text())
    assert d["parameters"] == pytest.approx(r["parameters"], abs=1e-12)
    assert d["mean_jvj"] == pytest.approx(r["mean_jvj"], rel=1e-12)


def test_a_planar_design_refuses_deg(tmp_path, capsys):
    """design --vary limits takes no angle: --deg is refused, not ignored."""
    code, _, err = run_cli(
        ["design", "--robot", "planar_3r", "--deg", "--out", str(tmp_path / "p")], capsys
    )
    assert code == 2 and "--deg: options of --vary dh" in err


def test_a_start_read_modulo_a_turn_is_printed_where_the_run_starts(capsys):
    """5.5 rad on a full-turn joint (limits ±π) runs from 5.5 − 2π; the start line says so."""
    code, out, err = run_cli(
        ["simulate", "--robot", "planar_3r", "--q0=0.3,1.2,5.5", "--algorithms", "jvja", *SHORT],
        capsys,
    )
    assert code == 0, err
    (line,) = start_lines(out)
    wrapped = round(5.5 - 2 * np.pi, 4)
    assert line == (
        f"start: q0 = [0.3, 1.2, {wrapped}] rad (given by --q0; joint3 read modulo 2π into the "
        "limits)"
    )
    assert f"start: every method from the same q0 = [0.3, 1.2, {wrapped}] rad" in out


# -- the degrees hint only where the values are degree-sized -----------------------------------


def test_a_radian_start_a_little_past_a_limit_gets_no_degrees_hint(capsys):
    """Panda joint2 at -1.77 rad, 0.007 past its limit: refused naming it, with no degrees hint."""
    code, out, err = run_cli(
        ["simulate", "--robot", "panda", "--q0=0,-1.77,0,-2,0,1.5,0.7", *SHORT], capsys
    )
    assert code == 2 and out == ""
    assert "panda_joint2 = -1.77 rad (limits [-1.763, 1.763] rad)" in err
    assert "degrees" not in err and "--deg" not in err


def test_beyond_pi_but_outside_once_converted_gets_no_degrees_hint(panda):
    """3.5 on panda_joint4 (limits [-3.07, -0.07]): 3.5° is outside too, so no degrees hint."""
    q = PANDA_Q.copy()
    q[3] = 3.5
    with pytest.raises(ft.InvalidInput, match="panda_joint4 = 3.5 rad") as err:
        check_start(panda, q)
    assert "degrees" not in str(err.value)


def test_a_start_found_for_x0_outside_the_limits_is_refused_without_a_degrees_hint(
    monkeypatch, capsys
):
    """The minimum-RCN start at --x0 is the tool's, not the user's: no degrees hint."""
    from fault_tolerance.planning import posture

    arm = ft.load_arm("panda", task="position")
    q = PANDA_Q.copy()
    q[3] = -3.08  # just below panda_joint4's lower limit -3.0718
    monkeypatch.setattr(posture, "initial_posture", lambda *a, **k: posture.Posture(q, 0.0))
    x0 = ",".join(f"{v:.4f}" for v in arm.fk(PANDA_Q))
    code, out, err = run_cli(
        ["simulate", "--robot", "panda", "--task", "position", f"--x0={x0}", *SHORT], capsys
    )
    assert code == 2 and out == ""
    assert "the start found for --x0 lies outside the joint limits: panda_joint4 = -3.08 rad" in err
    assert "degrees" not in err


def test_x0_orientation_rows_beyond_a_turn_are_refused_with_the_hint():
    """rx = 90 without --deg is refused with the hint; 400° with --deg is refused without it."""
    arm = ft.load_arm("spatial_4r", task="pose")
    with pytest.raises(ft.InvalidInput, match="beyond a full turn.*rx = 90 rad") as err:
        task_values("0.1,0.2,0.3,90,0,0", "--x0", arm)
    assert str(err.value).endswith(DEGREES_OPTION_HINT)
    with pytest.raises(ft.InvalidInput, match="beyond a full turn") as err:
        task_values("0.1,0.2,0.3,400,0,0", "--x0", arm, deg=True)
    assert "degrees" not in str(err.value)
    np.testing.assert_allclose(task_values("0,0,0,6.2,0,-6.2", "--x0", arm)[3:], [6.2, 0, -6.2])


def test_workspace_limits_in_degrees_get_the_hint(tmp_path, capsys):
    """workspace --limits=-90:90,... without --deg: the range error says to pass --deg."""
    argv = ["workspace", "--robot", "planar_3r", "--out", str(tmp_path / "w")]
    code, out, err = run_cli([*argv, "--limits=-90:90,-90:90,-90:90"], capsys)
    assert code == 2 and out == ""
    assert "limits of joint1 [-90, 90] rad must be" in err and DEGREES_OPTION_HINT in err
    code, _, err = run_cli([*argv, "--limits=-3.2:1,-1:1,-1:1"], capsys)
    assert code == 2 and "limits of joint1 [-3.2, 1] rad" in err and "degrees" not in err


def test_workspace_limits_deg_converts_before_the_range_check():
    """parse_limits with deg=True: degrees inside the physical limits pass; no hint with deg on."""
    from fault_tolerance.analysis.workspace.closed_form import parse_limits

    arm = ft.load_arm("planar_3r")
    lim = parse_limits(arm, "-90:90,-90:90,-90:90", deg=True)
    np.testing.assert_allclose(lim, np.deg2rad([[-90, 90]] * 3))
    with pytest.raises(ft.InvalidInput, match="within the physical") as err:
        parse_limits(arm, "-400:90,-90:90,-90:90", deg=True)
    assert "degrees" not in str(err.value)


@pytest.mark.parametrize(
    "params, message",
    [
        ("theta2:-45:45", "--params theta2 [-45.0, 45.0] rad: DH angles alpha, theta must be"),
        ("upper2:30:170", "--params upper2 [30.0, 170.0] rad: revolute joint limits must be"),
        ("alpha2:{0|90}", "--params alpha2 [0.0, 90.0] rad: DH angles alpha, theta must be"),
    ],
)
def test_design_params_in_degrees_get_the_hint(params, message, tmp_path, capsys):
    """design --vary dh --params with degree-sized angles and no --deg: refused with the hint."""
    code, out, err = run_cli(
        ["design", "--vary", "dh", "--params", params, "--popsize", "4", "--generations", "0",
         "--rounds", "0", "--workers", "0", "--no-progress", "--out", str(tmp_path / "d")],
        capsys,
    )  # fmt: skip
    assert code == 2 and out == ""
    assert message in err and DEGREES_OPTION_HINT in err
    assert not (tmp_path / "d" / "design.json").exists()
