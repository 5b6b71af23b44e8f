"""Option errors at the API: each is a FaultToleranceError naming the input and what is allowed."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.paper.reproduce import reproduce
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath, FunctionPath, load_csv
from fault_tolerance.simulation.run import Run
from fault_tolerance.simulation.simulate import simulate

Q = np.array([0.3, 1.2, 1.0])  # a regular planar 3R configuration


def circle(x0=(0.35, 0.0), duration=0.05, **kw) -> CirclePath:
    """A short Fig. 2 circle."""
    return CirclePath(np.array(x0), 0.1, 2 * np.pi, duration, **kw)


# -- names ------------------------------------------------------------------------------------


def test_unknown_robot_lists_the_known_ones():
    """An unknown robot name: RobotNotFound listing shipped and example-robot-data robots."""
    with pytest.raises(ft.RobotNotFound, match="'plannar_3r' is not a shipped robot") as err:
        ft.load_arm("plannar_3r")
    assert "'planar_3r'" in str(err.value) and "'panda'" in str(err.value)


def test_unknown_tip_lists_the_frames():
    """An unknown tip frame: FrameNotFound listing the model's frames."""
    with pytest.raises(ft.FrameNotFound, match=r"'flange'.*'tool'"):
        ft.load_arm("planar_3r", tip="flange")


def test_unknown_active_joint_lists_the_joints():
    """An unknown active joint: JointNotFound listing the model's joints."""
    with pytest.raises(ft.JointNotFound, match=r"'joint9'.*\['joint1', 'joint2', 'joint3'\]"):
        ft.load_arm("planar_3r", joints=["joint1", "joint9"])


@pytest.mark.parametrize("task", ["x,y,q", ["x", "yaw"], "", "orientation", ["x", "x"]])
def test_task_rows_must_be_among_the_six(task):
    """Task rows outside x y z rx ry rz (or repeated, or none): InvalidTask listing the allowed."""
    with pytest.raises(ft.InvalidTask, match=r"rows|row"):
        ft.load_arm("planar_3r", task=task)


def test_unknown_lock_joint_lists_the_joints(planar_3r):
    """simulate(lock_joint=...) with an unknown joint: JointNotFound listing the active joints."""
    with pytest.raises(ft.JointNotFound, match=r"'elbow'.*'joint2'"):
        simulate(planar_3r.arm, circle(), "lnva", q0=Q, lock_joint="elbow", lock_time=0.01)


# -- lockable sets ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "lockable, match",
    [
        ([], "empty"),
        ("", "empty"),
        (["joint2", "joint2"], "listed twice"),
        (["joint2", 1], "listed twice"),  # the same joint by name and by index
        ([("joint1", "joint1")], "names a joint twice"),
        (
            ["shoulder"],
            r"'shoulder' is not an active joint; they are \['joint1', 'joint2', 'joint3'\]",
        ),
        ([("joint1", "joint2")], r"locks 2 joints.*r = 1"),
        ([5], "out of range"),
    ],
)
def test_bad_lockable_sets_are_refused(planar_3r, lockable, match):
    """Empty, duplicate, unknown or too-large (|S| > r) lockable sets: InvalidScenario saying so,
    from the resolvers and from simulate alike."""
    arm = planar_3r.arm
    J = arm.jacobian(Q)
    with pytest.raises(ft.InvalidScenario, match=match):
        ft.resolve("jvja", J, np.array([0.1, 0.0]), lockable, joint_names=arm.joint_names)
    with pytest.raises(ft.InvalidScenario, match=match):
        simulate(arm, circle(), "lnva", q0=Q, lockable=lockable)


def test_no_redundancy_means_no_joint_may_lock():
    """A task with as many rows as joints (r = 0): any lockable joint is refused, saying why."""
    arm = ft.load_arm("planar_3r", task=["x", "y", "rz"])
    with pytest.raises(ft.InvalidScenario, match=r"no redundancy for this task \(r = n - m = 0\)"):
        ft.resolve(
            "jvja",
            arm.jacobian(Q),
            np.array([0.1, 0.0, 0.0]),
            ["joint1"],
            joint_names=arm.joint_names,
        )


def test_intolerable_scenario_is_refused_before_any_step(spatial_4r):
    """The 4R's joint4 (N44 = 0): IntolerableFailure naming it, from the resolver and from
    simulate before its first step (no progress reported, nothing integrated)."""
    arm = spatial_4r.arm
    q = np.array([0.3, 0.5, 0.2, 1.0])
    with pytest.raises(ft.IntolerableFailure, match="joint4") as err:
        ft.resolve(
            "jvja",
            arm.jacobian(q),
            np.array([0.0, 0.1, 0.0]),
            ["joint4"],
            joint_names=arm.joint_names,
        )
    assert err.value.joints == ["joint4"]
    ticks = []
    path = CirclePath(arm.fk(q), 0.05, 2 * np.pi, 0.05, rows=(1, 2))
    for alg in ("lnva", "jvja", "mda"):
        with pytest.raises(ft.IntolerableFailure, match="remove joint4 from the lockable joints"):
            simulate(
                arm,
                path,
                alg,
                q0=q,
                lockable=["joint1", "joint4"],
                progress=lambda k, n: ticks.append(k),
            )
    assert ticks == []


# -- numbers ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "dt, match",
    [
        (0.0, "dt must be"),
        (-1e-3, "dt must be"),
        (np.nan, "dt must be"),
        (np.inf, "dt must be"),
        (1.0, "longer than the run"),
    ],
)
def test_bad_time_step_is_refused(planar_3r, dt, match):
    """dt <= 0, not finite, or longer than the run: InvalidInput."""
    with pytest.raises(ft.InvalidInput, match=match):
        simulate(planar_3r.arm, circle(), "lnva", q0=Q, dt=dt)


@pytest.mark.parametrize("duration", [0.0, -1.0, np.nan])
def test_bad_duration_is_refused(planar_3r, duration):
    """A run or circle of non-positive or non-finite duration: InvalidInput."""
    with pytest.raises(ft.InvalidInput, match="duration must be"):
        simulate(planar_3r.arm, circle(), "lnva", q0=Q, duration=duration)
    with pytest.raises(ft.InvalidInput, match="duration must be"):
        circle(duration=duration)


@pytest.mark.parametrize(
    "q0",
    [[0.3, 1.2], [0.3, 1.2, 1.0, 0.0], [0.3, np.nan, 1.0], [np.inf, 0.0, 0.0], [[0.3, 1.2, 1.0]]],
)
def test_bad_configuration_is_refused(planar_3r, q0):
    """A q of the wrong length or with non-finite entries: InvalidInput naming the expected shape
    and joints (simulate, fk, jacobian)."""
    arm = planar_3r.arm
    for call in (
        lambda: simulate(arm, circle(), "lnva", q0=q0),
        lambda: arm.fk(q0),
        lambda: arm.jacobian(q0),
    ):
        with pytest.raises(ft.InvalidInput, match=r"shape \(3,\)|finite"):
            call()


def test_bad_resolver_inputs_are_refused(planar_3r):
    """Unknown algorithm or response, non-finite J or ẋ, mismatched shapes: InvalidInput (also a
    ValueError) listing what is allowed."""
    J = planar_3r.arm.jacobian(Q)
    with pytest.raises(
        ft.InvalidInput, match=r"'jvjaa' is not one of \['jvja', 'jvja_inertia', 'lnva', 'mda'\]"
    ):
        ft.resolve("jvjaa", J, np.array([0.1, 0.0]))
    with pytest.raises(ft.InvalidInput, match="'both' is not one of"):
        ft.resolve("jvja", J, np.array([0.1, 0.0]), response="both")
    with pytest.raises(ft.InvalidInput, match="finite"):
        ft.resolve("lnva", J, np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match=r"xdot \(m,\)"):
        ft.resolve("lnva", J, np.array([0.1, 0.0, 0.0]))
    with pytest.raises(ft.InvalidInput, match="'both' is not one of"):
        simulate(planar_3r.arm, circle(), "jvja", q0=Q, response="both")
    with pytest.raises(ft.InvalidInput, match="algorithm 'fast'"):
        simulate(planar_3r.arm, circle(), "fast", q0=Q)


def test_path_of_the_wrong_size_or_not_finite_is_refused(planar_3r):
    """A path with the wrong number of coordinates, or one that turns non-finite mid-run:
    InvalidInput (the latter naming the time)."""
    arm = planar_3r.arm
    with pytest.raises(ft.InvalidInput, match="3 coordinates, the task x/y has 2"):
        simulate(arm, CirclePath(np.array([0.35, 0.0, 0.0]), 0.1, 1.0, 0.05), "lnva", q0=Q)
    x0 = arm.fk(Q)
    bad = FunctionPath(lambda t: x0 if t < 0.02 else x0 * np.nan, 0.05, lambda t: np.zeros(2))
    with pytest.raises(ft.InvalidInput, match=r"at t = 0.02 s; it must give 2 finite numbers"):
        simulate(arm, bad, "lnva", q0=Q)


@pytest.mark.parametrize("key", ["radius", "omega", "sign"])
def test_circle_parameters_must_be_finite(key):
    """A circle with a non-finite radius, rate or sign: InvalidInput naming it."""
    kw = {"x0": np.array([0.35, 0.0]), "radius": 0.1, "omega": 1.0, "duration": 1.0, key: np.nan}
    with pytest.raises(ft.InvalidInput, match=f"circle {key} must be a finite number"):
        CirclePath(**kw)


def test_lock_time_outside_the_run_is_refused(planar_3r):
    """A lock time outside [0, duration] (or missing): InvalidInput giving the range."""
    for t in (None, -0.1, 0.2, np.nan):
        with pytest.raises(ft.InvalidInput, match=r"lock time must be within \[0, 0.05\]"):
            simulate(planar_3r.arm, circle(), "lnva", q0=Q, lock_joint="joint2", lock_time=t)


@pytest.mark.parametrize(
    "x0, match",
    [
        ((3.0, 0.0), "out of reach"),
        ((1.5, 0.0), "edge"),
        ((0.35,), "2 finite numbers"),
        ((np.nan, 0.0), "finite"),
    ],
)
def test_start_point_out_of_reach_is_refused(planar_3r, x0, match):
    """x0 outside the workspace, on its edge (reached only at a singular configuration), of the
    wrong size or not finite: InvalidInput."""
    with pytest.raises(ft.InvalidInput, match=match):
        initial_posture(planar_3r.arm, np.array(x0))


# -- CSV paths ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, match",
    [
        ("", "empty"),
        ("x,y\n0,0\n", "first column must be 't'"),
        ("t,x\n0,0.35\n1,0.4\n", r"columns \['y'\] not found"),
        ("t,x,x,y\n0,1,1,0\n1,1,1,0\n", r"columns \['x'\] appear twice"),
        ("t,x,y\n0,0.35,0\n0.5,0.36\n", r":3: 2 fields, the header has 3"),
        ("t,x,y\n0,0.35,0\n0.5,abc,0\n", r":3: a field is not a number"),
        ("t,x,y\n0,0.35,0\n0.5,inf,0\n", r":3: fields must be finite"),
        ("t,x,y\n0,0.35,0\n0.5,0.36,0\n0.5,0.37,0\n", r":4: t = 0.5 does not increase \(line 3"),
        ("t,x,y\n0,0.35,0\n", "at least 2 data rows"),
    ],
)
def test_bad_csv_paths_name_the_file_and_line(tmp_path, text, match):
    """CSV paths with bad rows: InvalidInput naming the file, the line and the problem."""
    path = tmp_path / "path.csv"
    path.write_text(text)
    with pytest.raises(ft.InvalidInput, match=match) as err:
        load_csv(path, rows=["x", "y"])
    assert "path.csv" in str(err.value)


def test_csv_from_a_spreadsheet_with_a_bom_loads(tmp_path):
    """A UTF-8 byte-order mark (as spreadsheets write) does not hide the 't' column."""
    path = tmp_path / "path.csv"
    path.write_bytes(b"\xef\xbb\xbft,x,y\r\n0,0.35,0\r\n0.5,0.36,0.01\r\n")
    assert load_csv(path).duration == 0.5


def test_csv_that_is_not_utf8_is_refused(tmp_path):
    """A CSV path in another encoding (or binary): InvalidInput, not a UnicodeDecodeError."""
    path = tmp_path / "path.csv"
    path.write_bytes("t,x,y\n0,0.35,0\n0.5,0.36,0 # caf\xe9\n".encode("latin-1"))
    with pytest.raises(ft.InvalidInput, match="not UTF-8"):
        load_csv(path)
    with pytest.raises(ft.InvalidInput, match="no such CSV file"):
        load_csv(tmp_path / "missing.csv")


# -- files --------------------------------------------------------------------------------------


def test_output_folder_that_is_a_file_is_refused_before_any_work(tmp_path, planar_3r, monkeypatch):
    """Run.save and reproduce into a path that is a file: InvalidInput; reproduce refuses before
    running a case."""
    blocker = tmp_path / "out"
    blocker.write_text("not a folder")
    run = simulate(planar_3r.arm, circle(duration=0.01), "lnva", q0=Q)
    with pytest.raises(ft.InvalidInput, match="exists and is not a folder"):
        run.save(blocker)
    import fault_tolerance.paper.reproduce as experiments

    monkeypatch.setattr(experiments, "run_case", lambda *a, **k: pytest.fail("a case ran"))
    with pytest.raises(ft.InvalidInput, match="exists and is not a folder"):
        reproduce(blocker, cases=["fig2"], quick=True, progress=False)
    with pytest.raises(ft.InvalidInput, match=r"unknown case\(s\) \['fig5'\]; choose among"):
        reproduce(tmp_path / "new", cases=["fig5"], quick=True, progress=False)


def test_loading_a_run_that_is_not_there_is_refused(tmp_path):
    """Run.load of a folder without run.npz, or of a file that is not a run: InvalidInput."""
    with pytest.raises(ft.InvalidInput, match="no saved run here"):
        Run.load(tmp_path)
    (tmp_path / "run.npz").write_bytes(b"garbage")
    with pytest.raises(ft.FaultToleranceError, match="no completion record"):
        Run.load(tmp_path)  # not written whole by Run.save
    from fault_tolerance.storage.result_folder import write_record

    write_record(tmp_path)  # a record that matches the garbage: the file itself is refused
    with pytest.raises(ft.InvalidInput, match="not a readable run file"):
        Run.load(tmp_path)


def test_every_error_is_a_fault_tolerance_error():
    """The toolkit's exceptions share one base; InvalidInput is also a ValueError."""
    for cls in (
        ft.RobotNotFound,
        ft.JointNotFound,
        ft.FrameNotFound,
        ft.URDFError,
        ft.InvalidTask,
        ft.InvalidScenario,
        ft.IntolerableFailure,
        ft.InvalidInput,
    ):
        assert issubclass(cls, ft.FaultToleranceError)
    assert issubclass(ft.InvalidInput, ValueError)
