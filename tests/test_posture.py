"""Initial posture (Sec. III.D step i) and the planning loop (steps ii-iii)."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.planning.paper_loop import plan
from fault_tolerance.planning.posture import (
    initial_posture,
    inverse_kinematics,
    self_motion_curve,
    square_sum_rcn_at,
)
from fault_tolerance.resolution.scenarios import scenarios
from fault_tolerance.simulation.paths import CirclePath


@pytest.fixture(scope="module")
def arm3():
    return ft.load_arm("planar_3r")


def _dense_minimum(arm, x0, sc):
    """K over a dense sampling of the whole self-motion manifold of a planar 3R.

    The manifold is sampled by the tool angle φ: the wrist point is x0 − L3 (cos φ, sin φ) and
    each φ has up to two elbow solutions, found by inverse kinematics from both elbow seeds.
    """
    best = np.inf
    for phi in np.linspace(-np.pi, np.pi, 721):
        for elbow in (1.0, -1.0):
            seed = np.array([phi - elbow * 1.0, elbow * 2.0, -elbow * 1.0])
            q = inverse_kinematics(arm, x0, seed)
            if q is not None:
                best = min(best, square_sum_rcn_at(arm, q, sc))
    return best


@pytest.mark.parametrize("x0", [[0.35, 0.0], [0.40, 0.0]])
def test_initial_posture_no_worse_than_dense_sampling(arm3, x0):
    """The global search finds a K no larger than a dense sampling of the self-motion manifold."""
    sc = scenarios("all", 3, r=1)
    P = initial_posture(arm3, np.array(x0))
    np.testing.assert_allclose(arm3.fk(P.q), x0, atol=1e-9)
    dense = _dense_minimum(arm3, np.array(x0), sc)
    assert P.K <= dense + 1e-9


def test_self_motion_curve_is_closed_and_on_the_task(arm3):
    """For r = 1 the traced self-motion curve closes and every point keeps x(q) = x0."""
    x0 = np.array([0.35, 0.0])
    q = inverse_kinematics(arm3, x0, np.array([0.5, 1.5, 1.0]))
    pts, closed = self_motion_curve(arm3, x0, q)
    assert closed
    err = max(np.linalg.norm(arm3.fk(p) - x0) for p in pts[::25])
    assert err < 1e-9


def test_posture_for_redundancy_above_one_improves_K():
    """For r > 1 (Panda position task) local descent lowers K from the IK seeds and keeps x0."""
    arm = ft.load_arm("panda", task="position")
    x0 = arm.fk(arm.q_reference)
    P = initial_posture(arm, x0, seeds=3)
    sc = scenarios("all", arm.n, r=arm.redundancy)
    assert P.K <= square_sum_rcn_at(arm, arm.q_reference, sc) + 1e-9
    np.testing.assert_allclose(arm.fk(P.q), x0, atol=1e-8)


def test_out_of_reach_start_is_refused(arm3):
    """A start point outside the workspace raises InvalidInput saying it is out of reach."""
    with pytest.raises(ft.InvalidInput, match="out of reach"):
        initial_posture(arm3, np.array([2.0, 0.0]), seeds=4)


def test_plan_reports_its_choice(arm3):
    """The planning loop accepts a start under the threshold, or says none met it."""
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.2)
    run, attempts = plan(arm3, path, "jvja", threshold=1e6)
    assert attempts[0].accepted and "<= threshold" in attempts[0].reason
    assert len(run.t) == 201
    run, attempts = plan(arm3, path, "jvja", threshold=1.0, max_attempts=2)
    assert not any(a.accepted for a in attempts)
    assert any("no start met the threshold" in a.reason for a in attempts)
