"""Units: position [m] and orientation [rad] errors are reported apart; λ carries (rad/s)²."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
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
