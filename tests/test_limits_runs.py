"""Runs with joint limits on: inside the limits before and after a lock, by default."""

import json
import subprocess
import sys

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.model.joint_limits import outside_limits, velocity_limits
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate

#: A generic Panda start inside its limits from which JVJA's unbounded rates leave them.
PANDA_Q0 = np.array([-1.304, -0.256, -2.004, -2.07, -0.32, 0.828, 0.54])


def _inside(arm, run):
    out = outside_limits(arm, run.q).any(axis=1)
    over = (np.abs(run.qd) > velocity_limits(arm) + 1e-9).any(axis=1)
    return int(out.sum()), int(over.sum())


def test_panda_leaves_its_limits_without_and_stays_inside_with_same_accuracy():
    arm = ft.load_arm("panda")
    path = CirclePath(x0=arm.fk(PANDA_Q0), radius=0.1, omega=np.pi, duration=1.0, rows=(0, 1))
    kw = dict(q0=PANDA_Q0, lockable=[0, 2, 4, 6], dt=2e-3, feedback_gain=10.0)
    paper = simulate(arm, path, "jvja", limits=False, **kw)
    bounded = simulate(arm, path, "jvja", **kw)  # limits on by default
    out, over = _inside(arm, paper)
    assert out > 0 and over > 0  # the paper's rates leave the limits
    assert _inside(arm, bounded) == (0, 0)
    s_paper, s = paper.summary(), bounded.summary()
    assert s["limits"] and not s_paper["limits"]
    assert (s["outside_position_limits_samples"], s["over_velocity_limit_samples"]) == (0, 0)
    assert s_paper["outside_position_limits_samples"] == out
    # the same tracking accuracy (here it is better: the paper's rates are too fast for Euler)
    assert s["tracking_error_max"] <= max(s_paper["tracking_error_max"], 1e-3)


@pytest.mark.parametrize("algorithm", ["lnva", "jvja", "mda"])
def test_lock_runs_stay_inside_before_and_after_the_lock(algorithm):
    arm = ft.load_arm("planar_3r")
    q0 = np.array([2.9, -2.5, 1.2])  # joints 1 and 2 near their limits
    path = CirclePath(x0=arm.fk(q0), radius=0.1, omega=2 * np.pi, duration=0.6, rows=(0, 1))
    run = simulate(
        arm,
        path,
        algorithm,
        q0=q0,
        lockable="all",
        lock_joint="joint3",
        lock_time=0.3,
        servo=ServoModel(tau=0.05),
        feedback_gain=10.0,
    )
    assert _inside(arm, run) == (0, 0)
    s = run.summary()
    assert s["outside_position_limits_samples"] == 0 and s["over_velocity_limit_samples"] == 0
    after = run.t >= 0.3
    assert np.all(run.qd[after, 2] == 0.0)
    paper = simulate(
        arm,
        path,
        algorithm,
        q0=q0,
        lockable="all",
        lock_joint="joint3",
        lock_time=0.3,
        servo=ServoModel(tau=0.05),
        feedback_gain=10.0,
        limits=False,
    )
    assert paper.summary()["limits"] is False


def test_start_outside_the_limits_is_refused_with_limits():
    arm = ft.load_arm("panda")
    q0 = PANDA_Q0.copy()
    q0[3] = 0.5  # above panda_joint4's upper limit (-0.07)
    path = CirclePath(x0=arm.fk(q0), radius=0.01, omega=np.pi, duration=0.01, rows=(0, 1))
    with pytest.raises(ft.InvalidInput, match="outside the joint limits.*panda_joint4"):
        simulate(arm, path, "lnva", q0=q0, lockable=[0])
    simulate(arm, path, "lnva", q0=q0, lockable=[0], limits=False)  # the paper's: allowed


@pytest.mark.slow
def test_cli_no_limits(tmp_path):
    q0 = ",".join(str(v) for v in PANDA_Q0)
    base = [
        sys.executable,
        "-m",
        "fault_tolerance",
        "simulate",
        "--robot",
        "panda",
        f"--q0={q0}",
        "--lockable",
        "panda_joint1,panda_joint3,panda_joint5,panda_joint7",
        "--radius",
        "0.1",
        "--omega",
        "3.14159",
        "--duration",
        "0.6",
        "--dt",
        "0.002",
        "--feedback",
        "10",
        "--algorithms",
        "jvja",
        "--no-progress",
    ]
    res = {}
    for flag, name in (([], "on"), (["--no-limits"], "off")):
        out = tmp_path / name
        p = subprocess.run(base + flag + ["--out", str(out)], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        assert "joint limits: " + name in p.stdout
        res[name] = json.loads((out / "jvja" / "summary.json").read_text())["summary"]
    assert res["off"]["outside_position_limits_samples"] > 0
    assert res["on"]["outside_position_limits_samples"] == 0
    assert res["on"]["over_velocity_limit_samples"] == 0
    for key in ("bound_active_samples", "task_scaled_samples"):
        assert key in res["on"]
