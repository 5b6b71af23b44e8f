"""Simulation: runs, their files, lock events and the servo model."""

from __future__ import annotations

import json

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.model.loading import arm_from_meta
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.run import ARRAYS, FLAG_LOCKED, Run
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate


@pytest.fixture(scope="module")
def setup3():
    arm = ft.load_arm("planar_3r")
    q0 = initial_posture(arm, np.array([0.35, 0.0])).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    return arm, q0, path


def test_run_reproduces_its_saved_file_exactly(setup3, tmp_path):
    """Saving, loading and re-simulating from the saved metadata give identical arrays."""
    arm, q0, path = setup3
    run = simulate(arm, path, "jvja", q0=q0, duration=0.3)
    run.save(tmp_path / "r")
    loaded = Run.load(tmp_path / "r")
    meta = loaded.meta
    again = simulate(
        arm_from_meta(meta),
        CirclePath(**{k: v for k, v in meta["path"].items() if k != "kind"}),
        meta["algorithm"],
        q0=np.array(meta["q0"]),
        lockable=[j for (j,) in meta["lockable"]],
        dt=meta["dt"],
        duration=meta["duration"],
    )
    for name in ARRAYS:
        assert np.array_equal(getattr(loaded, name), getattr(run, name)), name
        assert np.array_equal(getattr(again, name), getattr(run, name)), name
    assert loaded.meta == json.loads(json.dumps(run.meta))
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["summary"]["jvj_max"] == pytest.approx(float(run.jvj.max()))
    header = (tmp_path / "r" / "run.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "q_joint1", "q_joint2", "q_joint3"] and header[-1] == "flags"


@pytest.mark.parametrize("alg", ["lnva", "jvja", "mda"])
def test_closed_path_returns_to_start_within_tracking_error(setup3, alg):
    """After one full circle the tool is back at x0, within the run's reported tracking error."""
    arm, q0, path = setup3
    run = simulate(arm, path, alg, q0=q0)
    gap = np.linalg.norm(run.x[-1] - path.x0)
    assert gap <= run.summary()["tracking_error_max"] + 1e-12
    assert run.summary()["tracking_error_max"] < 2e-3  # explicit Euler at 1 ms on a 0.1 m circle


def test_feedback_bounds_the_drift(setup3):
    """Task-space feedback lowers the tracking error of the open-loop run."""
    arm, q0, path = setup3
    open_loop = simulate(arm, path, "jvja", q0=q0).summary()["tracking_error_max"]
    closed = simulate(arm, path, "jvja", q0=q0, feedback_gain=50.0).summary()["tracking_error_max"]
    assert closed < open_loop / 5


def test_jvja_rates_satisfy_the_task_along_the_run(setup3):
    """J q̇ = ẋ_cmd at every sample of an open-loop JVJA run."""
    arm, q0, path = setup3
    run = simulate(arm, path, "jvja", q0=q0, duration=0.2)
    for k in range(0, len(run.t), 50):
        np.testing.assert_allclose(
            arm.jacobian(run.q[k]) @ run.qd[k], path.xdot(run.t[k]), atol=1e-10
        )


def test_locking_a_joint_held_still_in_advance_costs_nothing(setup3):
    """Eq. (8): with only joint 3 lockable JVJA keeps it at rest; locking it adds no path error."""
    arm, q0, path = setup3
    servo = ServoModel(tau=0.05)
    free = simulate(arm, path, "jvja", q0=q0, lockable=["joint3"], servo=servo, feedback_gain=10.0)
    assert np.max(np.abs(free.qd[:, 2])) < 1e-12
    assert np.max(free.jvj) < 1e-20
    locked = simulate(
        arm,
        path,
        "jvja",
        q0=q0,
        lockable=["joint3"],
        servo=servo,
        feedback_gain=10.0,
        lock_joint="joint3",
        lock_time=0.4,
    )
    np.testing.assert_allclose(locked.error, free.error, atol=1e-10)
    assert locked.summary()["jump_at_lock"] < 1e-16
    assert np.all(locked.flags[locked.t >= 0.4] & FLAG_LOCKED)


def test_a_lock_with_a_jump_shows_up_as_path_error(setup3):
    """LNVA with a moving joint 2: locking it makes a path error beyond the servo lag alone."""
    arm, q0, path = setup3
    servo = ServoModel(tau=0.05)
    base = simulate(arm, path, "lnva", q0=q0, servo=servo, feedback_gain=10.0)
    run = simulate(
        arm,
        path,
        "lnva",
        q0=q0,
        servo=servo,
        feedback_gain=10.0,
        lock_joint="joint2",
        lock_time=0.3,
    )
    s = run.summary()
    assert s["jump_at_lock"] > 1e-2
    after = run.t >= 0.3
    np.testing.assert_array_equal(run.x[~after], base.x[~after])
    deviation = np.linalg.norm(run.x[after] - base.x[after], axis=1)
    assert deviation.max() > 1e-3  # [m]
    assert np.all(run.qd[after, 1] == 0.0)
    assert {k: run.meta["lock"][k] for k in ("joint", "index", "time")} == {
        "joint": "joint2",
        "index": 1,
        "time": 0.3,
    }


def test_servo_lag_is_exact_first_order():
    """The servo follows a step command as 1 − e^{−t/τ}; an acceleration limit caps the change."""
    s = ServoModel(tau=0.1)
    qd = np.zeros(1)
    for _ in range(100):
        qd = s.follow(qd, np.ones(1), 1e-3)
    assert qd[0] == pytest.approx(1 - np.exp(-1.0), abs=1e-12)
    lim = ServoModel(tau=0.0, accel_limit=10.0)
    assert lim.follow(np.zeros(1), np.ones(1), 1e-3)[0] == pytest.approx(0.01)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"dt": 0.0}, "dt must be"),
        ({"dt": -1e-3}, "dt must be"),
        ({"duration": np.inf}, "duration"),
        ({"lock_joint": "joint2", "lock_time": 5.0}, "lock time"),
        ({"lock_joint": "joint9", "lock_time": 0.1}, "joint9"),
        ({"feedback_gain": -1.0}, "feedback"),
    ],
)
def test_bad_simulation_options_are_refused(setup3, kwargs, match):
    """Bad time steps, durations, lock settings and gains raise the toolkit's errors."""
    arm, q0, path = setup3
    with pytest.raises(ft.FaultToleranceError, match=match):
        simulate(arm, path, "jvja", q0=q0, **kwargs)


def test_path_of_the_wrong_size_is_refused(setup3):
    """A 3-coordinate path on a 2-row task is refused with both sizes named."""
    arm, q0, _ = setup3
    with pytest.raises(ft.InvalidInput, match="3 coordinates"):
        simulate(arm, CirclePath([0, 0, 0], 0.1, 1.0, 1.0), "lnva", q0=q0)


def test_files_are_world_readable(setup3, tmp_path):
    """Atomic writes keep the usual permissions (not mkstemp's 0600)."""
    arm, q0, path = setup3
    simulate(arm, path, "lnva", q0=q0, duration=0.01).save(tmp_path)
    assert (tmp_path / "run.npz").stat().st_mode & 0o044 == 0o044
