"""diagnostics: each check fires on the problem it names, and stays quiet on the paper's good runs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.resolution.indices import RCN_THRESHOLD
from fault_tolerance.simulation import diagnostics as dg
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.run import FLAG_NEAR_SINGULAR, FLAG_OVER_SPEED
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate


@pytest.fixture(scope="module")
def arm():
    return ft.load_arm("planar_3r")


@pytest.fixture(scope="module")
def good(arm):
    """The paper's Fig. 2 run (planar 3R, JVJA from the minimum-K start, 1 s circle)."""
    q0 = initial_posture(arm, [0.35, 0.0]).q
    return simulate(arm, CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0), "jvja", q0=q0)


@pytest.fixture(scope="module")
def bad(arm):
    """A circle that leaves the workspace: rates 100x the limit, K of 1e7, the tool 0.4 m off.

    The paper's formulation (no joint limits): with the limits on the rates stay in the box."""
    q0 = initial_posture(arm, [1.3, 0.0]).q
    path = CirclePath([1.3, 0.0], 0.3, 2 * np.pi, 1.0)
    return simulate(arm, path, "jvja", q0=q0, limits=False)


def test_good_run_has_no_warning(arm, good):
    """The paper's Fig. 2 run passes every check."""
    assert dg.check_run(good, arm) == []
    assert dg.check_run(good) == []


def test_bad_run_is_reported(arm, bad):
    """The run the issue describes gets a warning for speed, RCN and tracking, one line each."""
    found = {w.kind: w.message for w in dg.check_run(bad, arm)}
    assert {"over_speed", "rcn", "tracking"} <= set(found), found
    ratio = float(found["over_speed"].split(" = ")[1].split(" x ")[0])
    assert ratio > 100 and "its 3 rad/s" in found["over_speed"]
    assert f"threshold {RCN_THRESHOLD:g}" in found["rcn"]
    assert float(found["tracking"].split()[2]) > 100  # mm
    lines = dg.warning_lines("jvja", dg.check_run(bad, arm))
    assert all("\n" not in line and line.startswith("warning: jvja: ") for line in lines)


def test_over_speed_uses_the_limits_or_the_flags(good):
    """Rates above the given limits are counted; without limits the run's flags are."""
    assert dg.over_speed(good, np.full(3, 3.0)) is None
    w = dg.over_speed(good, np.array([3.0, 0.1, 3.0]))
    assert w is not None and "joint2" in w.message
    flags = good.flags.copy()
    flags[[10, 20]] |= FLAG_OVER_SPEED
    w = dg.over_speed(dataclasses.replace(good, flags=flags))
    assert w is not None and w.message.startswith("2 of 1001 samples")
    assert dg.over_speed(good, np.full(3, np.inf)) is None  # no limit given: nothing to exceed


def test_rcn_beyond_threshold(good):
    """One sample with k_S above the threshold gives a warning naming the scenario and time."""
    rcn = good.rcn.copy()
    rcn[500, 1] = 10 * RCN_THRESHOLD
    w = dg.rcn_beyond(dataclasses.replace(good, rcn=rcn))
    assert w is not None and "1 of 1001" in w.message and "joint2 locked" in w.message
    assert "t = 0.5 s" in w.message
    assert dg.rcn_beyond(good) is None


def test_near_singular_samples(good):
    """Samples flagged near-singular are counted with their time span."""
    flags = good.flags.copy()
    flags[100:150] |= FLAG_NEAR_SINGULAR
    w = dg.near_singular(dataclasses.replace(good, flags=flags))
    assert w is not None and w.message.startswith("50 near-singular samples")
    assert "between t = 0.1 and 0.149 s" in w.message


def test_tracking_tolerance_is_strict(good):
    """An error just above TRACKING_TOLERANCE warns; one just below does not."""
    for scale, warns in ((1.01, True), (0.99, False)):
        err = good.error.copy()
        err[300] = scale * dg.TRACKING_TOLERANCE
        assert (dg.tracking_error(dataclasses.replace(good, error=err)) is not None) is warns


def test_lock_that_loses_the_path(arm):
    """A lock the reduced robot follows passes; 5 cm of error after it is 'loses the path'."""
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    kept = simulate(
        arm,
        path,
        "jvja",
        q0=q0,
        lock_joint="joint2",
        lock_time=0.3,
        feedback_gain=10,
        servo=ServoModel(tau=0.0),
    )
    assert dg.check_run(kept, arm) == []
    err = kept.error.copy()
    err[800] = 0.05
    w = dg.lock_loses_path(dataclasses.replace(kept, error=err))
    assert w is not None and "joint2" in w.message and "50 mm" in w.message
    # the error after the lock is not a tracking error of the planned run
    assert dg.tracking_error(dataclasses.replace(kept, error=err)) is None


def test_servo_lag_is_a_tracking_error_not_a_lost_path(arm):
    """With a 50 ms servo lag on a fast circle the tool lags ~2.5 cm before the lock: reported as
    tracking, and the lock (which adds little) is not blamed for it."""
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    run = simulate(arm, path, "jvja", q0=q0, lock_joint="joint2", lock_time=0.5, feedback_gain=10)
    kinds = [w.kind for w in dg.check_run(run, arm)]
    assert kinds == ["tracking"], kinds


def test_report_leaves_degenerate_starts_out_and_names_them():
    """A start whose runs broke a check is counted as left out, not averaged into the numbers."""
    from fault_tolerance.paper.report import _sensitivity_row

    good = {"jvj_mean_lnva": 2.0, "jvj_mean_jvja": 1.0, "degenerate": False, "warnings": []}
    bad = {"jvj_mean_lnva": 1.0, "jvj_mean_jvja": 900.0, "degenerate": True, "warnings": ["x"]}
    row = _sensitivity_row("fig2", {"starts": [good, good, bad]})
    assert row == "| fig2 | 100 % of 2 | 50.0 % | 1 of 3 |"
    assert _sensitivity_row("fig2", {"starts": [bad]}) == "| fig2 | - | - | 1 of 1 |"
