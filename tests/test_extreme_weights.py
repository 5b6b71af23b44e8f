"""Extreme scenario weights: scale-free rates, refused spans, warned scaling."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control.fast.bounded_solve import bounded_rates
from fault_tolerance.errors import FaultToleranceError
from fault_tolerance.simulation import diagnostics as dg
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.run import FLAG_TASK_SCALED
from fault_tolerance.simulation.simulate import simulate

EXTREME = (1e308, 5e-324, 1.0e-300, 1e300)


@pytest.fixture(scope="module")
def task():
    arm = ft.load_arm("planar_3r")
    q = np.array([0.3, 1.0, 0.8])
    return arm.jacobian(q), np.array([0.1, 0.2])


@pytest.mark.parametrize("response", ["least_norm", "continuation"])
@pytest.mark.parametrize("half_width", [0.05, 0.3, 5.0])  # scaled, some bounds active, inside
@pytest.mark.parametrize("w", EXTREME)
def test_bounded_jvja_rates_do_not_depend_on_the_scale_of_the_weights(
    task, response, half_width, w
):
    """Weights c·1 give the rates and scale of weights 1: never q̇ = 0 with s = 1 for ẋ ≠ 0."""
    J, xd = task
    box = (-half_width * np.ones(3), half_width * np.ones(3))
    ref = ft.resolve_bounded("jvja", J, xd, [0, 1, 2], response=response, bounds=box)
    out = ft.resolve_bounded(
        "jvja", J, xd, [0, 1, 2], weights=[w] * 3, response=response, bounds=box
    )
    assert np.all(np.isfinite(out.qd))
    np.testing.assert_allclose(out.qd, ref.qd, atol=1e-10)
    assert out.scale == pytest.approx(ref.scale, abs=1e-10)
    np.testing.assert_allclose(J @ out.qd, out.scale * xd, atol=1e-9)  # the task part is kept
    assert np.linalg.norm(out.qd) > 1e-3


@pytest.mark.parametrize("w", EXTREME)
def test_unequal_extreme_weights_weight_the_same_as_their_ratio(task, w):
    """Weights (2w, w, w) give the rates of (2, 1, 1), bounded and unbounded."""
    J, xd = task
    box = (-0.3 * np.ones(3), 0.3 * np.ones(3))
    big = [w, w, w] if w > 1e307 else [2 * w, w, w]
    small = [1.0, 1.0, 1.0] if w > 1e307 else [2.0, 1.0, 1.0]
    a = ft.resolve_bounded("jvja", J, xd, [0, 1, 2], weights=big, bounds=box)
    b = ft.resolve_bounded("jvja", J, xd, [0, 1, 2], weights=small, bounds=box)
    np.testing.assert_allclose(a.qd, b.qd, atol=1e-10)
    np.testing.assert_allclose(
        ft.resolve("jvja", J, xd, [0, 1, 2], weights=big),
        ft.resolve("jvja", J, xd, [0, 1, 2], weights=small),
        atol=1e-10,
    )


@pytest.mark.parametrize("w", [1e308, 5e-324])
def test_compiled_bounded_solve_is_scale_free(task, w):
    """The compiled bounded solve (control/fast) gives the rates of weights 1 for 1e308, 5e-324."""
    J, xd = task
    lo, hi = -0.3 * np.ones(3), 0.3 * np.ones(3)
    sets = [(0,), (1,), (2,)]
    code1, qd1, s1, _, _ = bounded_rates("jvja", J, xd, sets, lo, hi)
    code, qd, s, _, _ = bounded_rates("jvja", J, xd, sets, lo, hi, weights=[w] * 3)
    assert code == code1
    np.testing.assert_allclose(qd, qd1, atol=1e-10)
    assert s == pytest.approx(s1, abs=1e-12)


def test_weights_spanning_more_than_the_float_range_are_refused(task):
    """(1e308, 1, 5e-324): the smallest over the largest underflows; refused, naming the limit."""
    J, xd = task
    with pytest.raises(ft.InvalidScenario, match=r"ratio of inf.*within a ratio of 1e\+300"):
        ft.resolve_bounded(
            "jvja", J, xd, [0, 1, 2], weights=[1e308, 1.0, 5e-324], bounds=(-np.ones(3), np.ones(3))
        )
    with pytest.raises(FaultToleranceError, match="ratio"):
        ft.resolve("jvja", J, xd, [0, 1, 2], weights=[1e301, 1.0, 1.0])
    ft.resolve("jvja", J, xd, [0, 1, 2], weights=[1e300, 1.0, 1.0])  # at the limit: accepted


def test_simulate_with_extreme_weights_runs_like_weights_one():
    """A bounded JVJA run with weights 1e308 follows the path as the one with weights 1."""
    arm = ft.load_arm("planar_3r")
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0)
    q0 = ft.initial_posture(arm, [0.35, 0.0]).q
    ref = simulate(arm, path, "jvja", q0=q0, dt=0.01)
    big = simulate(arm, path, "jvja", q0=q0, dt=0.01, weights=[1e308] * 3)
    np.testing.assert_allclose(big.q, ref.q, atol=1e-9)
    np.testing.assert_allclose(big.error, ref.error, atol=1e-9)


def test_runs_with_a_scaled_task_are_counted_and_warned():
    """A circle too fast for the Panda's rate box: the scaled samples are counted and warned."""
    arm = ft.load_arm("panda")
    q0 = ft.default_start(arm, path=None).q0
    x0 = arm.fk(q0)
    path = CirclePath(x0, 0.2, 2 * np.pi, 0.3, rows=(0, 1))  # ~4 m/s: beyond the box
    run = simulate(arm, path, "jvja", q0=q0, dt=0.005)
    scaled = int(np.count_nonzero(run.flags & FLAG_TASK_SCALED))
    assert scaled > 0 and run.summary()["task_scaled_samples"] == scaled
    found = {w.kind: w.message for w in dg.check_run(run, arm)}
    assert f"{scaled} with the task scaled (s < 1)" in found["task_scaled"]


def test_zero_rates_while_the_path_moves_are_warned():
    """A run whose rates are zero while x_des moves gets the warning, with the count."""
    arm = ft.load_arm("planar_3r")
    q0 = ft.initial_posture(arm, [0.35, 0.0]).q
    run = simulate(arm, CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 1.0), "jvja", q0=q0, dt=0.01)
    assert dg.task_scaled(run) is None  # the paper's run keeps the whole task
    qd = run.qd_cmd.copy() if run.qd_cmd is not None else run.qd.copy()
    qd[10:15] = 0.0
    still = dataclasses.replace(run, qd=qd, qd_cmd=qd)
    w = dg.task_scaled(still)
    assert w is not None and "5 with zero rates while the path moves" in w.message
    assert "task_scaled" in {x.kind for x in dg.check_run(still, arm)}
