"""failures: scenario validation (MATH.md "Failure scenarios") and intolerable scenarios (G1)."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.resolution.scenarios import Scenarios

NAMES = ("joint1", "joint2", "joint3", "joint4")


# -- what is accepted -----------------------------------------------------------------------


@pytest.mark.parametrize("lockable", [None, "all"])
def test_all_joints_give_one_singleton_each(lockable):
    """None or 'all' means every joint may lock, one at a time, with weight 1."""
    sc = ft.scenarios(lockable, 4)
    assert sc.sets == ((0,), (1,), (2,), (3,))
    assert sc.f == 4 and sc.singletons
    np.testing.assert_array_equal(sc.weights, np.ones(4))
    np.testing.assert_array_equal(sc.columns, [0, 1, 2, 3])


def test_indices_names_and_comma_string_agree():
    """Column indices, joint names and a comma-separated string select the same scenarios."""
    a = ft.scenarios([1, 2], 4, joint_names=NAMES)
    b = ft.scenarios(["joint2", "joint3"], 4, joint_names=NAMES)
    c = ft.scenarios("joint2, joint3", 4, joint_names=NAMES)
    d = ft.scenarios(np.array([1, 2]), 4)
    assert a.sets == b.sets == c.sets == d.sets == ((1,), (2,))


def test_multi_joint_scenarios_are_sorted_tuples():
    """Tuples are multi-joint scenarios; their columns are sorted and may mix names and indices."""
    sc = ft.scenarios([(3, 0), ("joint2", 2)], 7, r=4, joint_names=NAMES + ("a", "b", "c"))
    assert sc.sets == ((0, 3), (1, 2))
    assert not sc.singletons


def test_weights_are_kept_in_order():
    """Weights are one per scenario, in the order given."""
    sc = ft.scenarios([0, (1, 2)], 4, r=2, weights=[0.5, 2.0])
    np.testing.assert_array_equal(sc.weights, [0.5, 2.0])


def test_ready_scenarios_pass_through():
    """A validated Scenarios object is returned as is."""
    sc = ft.scenarios([0, 2], 3)
    assert ft.scenarios(sc, 3) is sc


def test_scenario_names_for_messages():
    """Scenarios.name gives joint names when known and 'joint index i' otherwise."""
    assert ft.scenarios([0, 3], 4, joint_names=NAMES).name((3,)) == ["joint4"]
    assert ft.scenarios([0, 3], 4).name((3,)) == ["joint index 3"]


# -- what is refused ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "lockable, kwargs, match",
    [
        ([], {}, "empty"),
        ("", {}, "empty"),
        ([()], {}, "empty"),
        ([1, 1], {}, "listed twice"),
        ([(0, 1), (1, 0)], {"r": 2}, "listed twice"),
        (["joint2", 1], {"joint_names": NAMES}, "listed twice"),
        ([(1, 1)], {"r": 2}, "twice"),
        ([4], {}, r"out of range; allowed 0\.\.3"),
        ([-1], {}, "out of range"),
        ([(0, 7)], {"r": 2}, "out of range"),
        (["joint9"], {"joint_names": NAMES}, r"joint9.*\['joint1', 'joint2', 'joint3', 'joint4'\]"),
        (["joint2"], {}, "no joint names are known"),
        ([True], {}, "not a column index"),
        ([1.5], {}, "not a column index"),
        ([(0, 1)], {"r": 1}, "r = 1"),
        ([(0, 1, 2)], {"r": 2}, "at most 2 joints"),
        ([0, 1], {"weights": [1.0]}, "1 weights for 2 scenarios"),
        ([0, 1], {"weights": [1.0, 2.0, 3.0]}, "3 weights for 2 scenarios"),
        ([0, 1], {"weights": [1.0, 0.0]}, "> 0"),
        ([0, 1], {"weights": [1.0, -2.0]}, "> 0"),
        ([0, 1], {"weights": [1.0, np.nan]}, "finite"),
        ([0, 1], {"weights": [np.inf, 1.0]}, "finite"),
    ],
)
def test_invalid_scenarios_raise_with_a_helpful_message(lockable, kwargs, match):
    """Empty, duplicate, out-of-range, unknown, oversized or badly weighted scenarios: refused."""
    with pytest.raises(ft.InvalidScenario, match=match) as err:
        ft.scenarios(lockable, 4, **kwargs)
    assert isinstance(err.value, ft.FaultToleranceError)


def test_scenarios_dataclass_validates_itself():
    """Scenarios built directly are validated too (empty set, weight count)."""
    with pytest.raises(ft.InvalidScenario):
        Scenarios((), np.ones(0), 3)
    with pytest.raises(ft.InvalidScenario):
        Scenarios(((0,),), np.ones(2), 3)


@pytest.mark.parametrize("resolver", ["jvja", "mda"])
def test_resolvers_validate_scenarios(planar_3r, resolver):
    """Resolvers refuse a scenario larger than r with InvalidScenario (r = 1 on the planar 3R)."""
    arm = planar_3r.arm
    q = np.array([0.3, 1.2, 1.0])
    with pytest.raises(ft.InvalidScenario, match="r = 1"):
        ft.resolve(resolver, arm.jacobian(q), np.array([0.1, 0.0]), lockable=[(0, 1)], arm=arm, q=q)
    with pytest.raises(ft.InvalidScenario, match="empty"):
        ft.resolve(resolver, arm.jacobian(q), np.array([0.1, 0.0]), lockable=[], arm=arm, q=q)


# -- intolerable scenarios (G1) -------------------------------------------------------------


def test_spatial_4r_joint4_is_intolerable_everywhere(spatial_4r, rng, draw_xdot):
    """The 4R's joint4 (index 3) has N₃₃ = 0 everywhere: JVJA refuses it, naming joint4."""
    arm = spatial_4r.arm
    for _ in range(50):
        q = arm.random_q(rng)
        J = arm.jacobian(q)
        if np.linalg.svd(J, compute_uv=False)[-1] < 1e-2:
            continue  # the pivot is only meaningful with J of full rank
        np.testing.assert_allclose(ft.nullspace_projector(J)[3, 3], 0.0, atol=1e-10)
        xd = draw_xdot(rng, 3)
        with pytest.raises(ft.IntolerableFailure, match="joint4") as err:
            ft.resolve("jvja", J, xd, lockable=[3], joint_names=arm.joint_names)
        assert err.value.joints == ["joint4"]
        assert err.value.pivot < 1e-9
        assert "remove joint4 from the lockable joints" in str(err.value)


def test_intolerable_joint_is_found_among_tolerable_ones(spatial_4r, rng, draw_q, draw_xdot):
    """With lockable 'all' on the 4R, JVJA and jvj refuse the scenario of joint4 and no other."""
    arm = spatial_4r.arm
    q = draw_q(spatial_4r, rng)
    J = arm.jacobian(q)
    xd = draw_xdot(rng, 3)
    for response in ("least_norm", "continuation"):
        with pytest.raises(ft.IntolerableFailure, match="joint4"):
            ft.jvja(J, xd, "all", joint_names=arm.joint_names, response=response)
    with pytest.raises(ft.IntolerableFailure, match="joint index 3"):
        ft.jvj(J, xd, ft.lnva(J, xd), "all")
    ft.jvja(J, xd, [0, 1, 2])  # the paper's lockable set is fine


def test_multi_joint_scenario_with_singular_pivot_block_is_intolerable():
    """A multi-joint scenario is intolerable when N[S, S] is singular (the task is lost)."""
    # joints 1 and 2 drive x and y alone; locking joint1 with joint3 leaves x uncontrollable
    J = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    N = ft.nullspace_projector(J)
    ok = ft.scenarios([(2, 3)], 4, r=2, joint_names=NAMES)
    np.testing.assert_allclose(ok.check_tolerable(N), [1.0], atol=1e-12)
    bad = ft.scenarios([(2, 3), (0, 2)], 4, r=2, joint_names=NAMES)
    with pytest.raises(ft.IntolerableFailure, match="joint1, joint3") as err:
        bad.check_tolerable(N)
    assert err.value.joints == ["joint1", "joint3"]
    with pytest.raises(ft.IntolerableFailure):
        ft.jvja(J, np.array([0.1, 0.2]), [(2, 3), (0, 2)])


def test_check_tolerable_returns_the_pivots(robot, rng, draw_q):
    """check_tolerable returns the pivots N[i, i] of the singleton scenarios."""
    J = robot.arm.jacobian(draw_q(robot, rng))
    N = ft.nullspace_projector(J)
    sc = ft.scenarios(list(robot.lockable), robot.n, r=robot.r)
    np.testing.assert_allclose(sc.check_tolerable(N), np.diag(N)[list(robot.lockable)], atol=1e-12)
