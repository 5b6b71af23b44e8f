"""start: the default start is inside the limits, regular, tolerant, and runs the default task."""

from __future__ import annotations

import re

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.linalg import projection
from fault_tolerance.planning import start_checks as st
from fault_tolerance.planning.default_start import check_start
from fault_tolerance.planning.posture import lockable_scenarios
from fault_tolerance.simulation.run import FLAG_NEAR_SINGULAR


def _assert_good_start(arm, choice, lockable=None):
    sc = lockable_scenarios(arm, lockable)
    assert st.inside_limits(arm, choice.q0, st.LIMIT_MARGIN)
    proj = projection(arm.jacobian(choice.q0))
    assert proj.sigma_min >= st.SIGMA_REGULAR
    assert sc.pivots(proj.N).min() >= st.PIVOT_MARGIN
    np.testing.assert_allclose(arm.fk(choice.q0), choice.x0, atol=1e-8)


@pytest.mark.parametrize("name", ["planar_3r", "ur5"])
def test_default_start_is_good_and_its_run_stays_inside(name):
    """The chosen start is regular and inside the limits; the checked run never leaves them."""
    arm = ft.load_arm(name)
    choice = ft.default_start(arm)
    _assert_good_start(arm, choice)
    run = choice.runs["jvja"]
    assert st.inside_limits(arm, run.q).all()
    assert not np.any(run.flags & FLAG_NEAR_SINGULAR)
    assert run.error.max() < st.ERROR_TOL
    assert "\n" not in choice.reason() and "q0 = " in choice.reason()


def test_q_zero_and_mid_range_are_refused_where_singular():
    """A UR5 at q = 0 (its mid-range) is stretched out and cannot lose its shoulder pan: not a start."""
    arm = ft.load_arm("ur5")
    sc = lockable_scenarios(arm, None)
    np.testing.assert_allclose(st.mid_range(arm), 0.0)
    assert "locking shoulder_pan_joint nearly loses the task" in st.start_problem(
        arm, np.zeros(6), sc
    )
    assert np.linalg.norm(ft.default_start(arm).q0) > 0.5


def test_panda_reference_posture_is_refused_and_default_start_works():
    """At the Panda's reference posture a lockable joint is (nearly) intolerable; the start is not."""
    pose = ft.load_arm("panda")
    problem = st.start_problem(pose, pose.q_reference, lockable_scenarios(pose, "all"))
    # joints 2 and 4 both lose the task there (pivots at rounding level): either may be named
    N = np.eye(pose.n) - np.linalg.pinv(pose.jacobian(pose.q_reference)) @ pose.jacobian(
        pose.q_reference
    )
    named = re.search(r"locking (panda_joint\d) nearly loses the task", problem)
    assert named is not None, problem
    j = pose.joint_names.index(named.group(1))
    assert abs(N[j, j]) < 1e-9 and named.group(1) in ("panda_joint2", "panda_joint4")
    arm = ft.load_arm("panda", task="position")
    choice = ft.default_start(arm, "all")
    _assert_good_start(arm, choice, "all")


def test_default_start_is_reproducible():
    """The same arm and options give the same start (seeded)."""
    arm = ft.load_arm("planar_3r")
    np.testing.assert_array_equal(ft.default_start(arm).q0, ft.default_start(arm).q0)


def test_given_x0_keeps_the_point():
    """With x0 given, the start reaches it (posture search at x0) and is checked the same way."""
    arm = ft.load_arm("planar_3r")
    choice = ft.default_start(arm, x0=[0.35, 0.0], algorithms=("lnva",))
    np.testing.assert_allclose(choice.x0, [0.35, 0.0])
    _assert_good_start(arm, choice)
    assert choice.origin == "given x0"


def test_no_start_is_a_clear_error():
    """A point out of reach gives InvalidInput naming the arm and the reason's category."""
    arm = ft.load_arm("planar_3r")
    with pytest.raises(ft.NoStartFound, match="no start at x0 .* 1 path out of reach") as err:
        ft.default_start(arm, x0=[3.0, 0.0])
    assert isinstance(err.value, ft.InvalidInput)
    assert err.value.reasons == [("path out of reach", 1, ())]


def test_path_too_large_is_refused_with_reason():
    """A task that leaves the workspace from every candidate is refused, with the last reason."""
    from fault_tolerance.simulation.paths import CirclePath

    arm = ft.load_arm("planar_3r")
    big = lambda x0: CirclePath(x0, 2.0, 2 * np.pi, 1.0)  # noqa: E731
    with pytest.raises(ft.InvalidInput, match="passed the checks"):
        ft.default_start(arm, path=big, algorithms=("lnva",), max_seeds=2)


def test_task_error_parts_separate_units():
    """Position [m] and orientation [rad] errors are separate norms, never added."""
    pos, ori = st.task_error_parts(
        ("x", "y", "z", "rx", "ry", "rz"), [[0.0, 0, 0, 0, 0, 0]], [[0.003, 0.004, 0, 0, 0, 0.5]]
    )
    np.testing.assert_allclose(pos, [0.005])
    np.testing.assert_allclose(ori, [0.5])
    pos, ori = st.task_error_parts(("x", "y"), [[0.0, 0.0]], [[0.0, 0.002]])
    assert ori is None and pos[0] == pytest.approx(0.002)


def test_structurally_intolerable_joint_is_named_so():
    """The 4R's joint 4 is intolerable everywhere: the error says structurally, no start helps."""
    arm = ft.load_arm("spatial_4r")
    assert st.intolerable_everywhere(arm, ["joint1", "joint4"]) == [("joint4",)]
    q = np.array([0.3, 0.4, 0.5, 1.0])
    with pytest.raises(ft.StructurallyIntolerable, match="structurally"):
        check_start(arm, lockable_scenarios(arm, ["joint1", "joint4"]), q)


def test_intolerable_at_this_start_proposes_a_start_that_works():
    """Panda (position task) at its reference posture: intolerable here only; the q0 it proposes works."""
    arm = ft.load_arm("panda", task="position")
    sc = lockable_scenarios(arm, [("panda_joint2", "panda_joint4")])
    with pytest.raises(ft.IntolerableAtStart, match="at this start only.*--q0 ") as info:
        check_start(arm, sc, arm.q_reference, algorithms=("lnva",))
    assert not isinstance(info.value, ft.StructurallyIntolerable)
    q0 = np.array(info.value.q0)
    assert sc.pivots(projection(arm.jacobian(q0)).N).min() >= st.PIVOT_MARGIN
    assert st.inside_limits(arm, q0, st.LIMIT_MARGIN)


def test_proposal_keeps_the_start_point_when_it_can():
    """Given the start point, the proposed start is another posture at that same point."""
    arm = ft.load_arm("panda", task="position")
    sc = lockable_scenarios(arm, [("panda_joint2", "panda_joint4")])
    x0 = arm.fk(arm.q_reference)
    with pytest.raises(ft.IntolerableAtStart, match="same start point") as info:
        check_start(arm, sc, arm.q_reference, x0=x0, algorithms=("lnva",))
    np.testing.assert_allclose(arm.fk(np.array(info.value.q0)), x0, atol=1e-8)


def test_a_refused_candidate_is_one_refused_candidate(monkeypatch):
    """A run that raises InfeasibleBounds from one candidate start refuses that candidate only."""
    import fault_tolerance.simulation.simulate as simulation

    real, calls = simulation.simulate, []

    def first_refused(*args, **kwargs):
        calls.append(kwargs.get("q0"))
        if len(calls) == 1:
            raise ft.InfeasibleBounds("the task scaling did not converge (injected)")
        return real(*args, **kwargs)

    monkeypatch.setattr(simulation, "simulate", first_refused)
    arm = ft.load_arm("planar_3r")
    choice = ft.default_start(arm)
    assert len(calls) >= 2 and choice.tried >= 2
    assert not np.allclose(choice.q0, calls[0])  # the refused candidate was not chosen
