"""The posture search's lean steps give the plain steps' numbers, bit for bit (posture_steps).

The golden-section refinement of the best curve point amplifies any rounding difference to
~1e-8 rad of the chosen start, so "close" is not enough: every step and the whole search are
compared for equality, on the shipped arms, on example-robot-data arms and on pose tasks.
"""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.failures import scenarios
from fault_tolerance.linalg import SIGMA_EPS, projection
from fault_tolerance.posture import initial_posture, inverse_kinematics, self_motion_curve
from fault_tolerance.posture_steps import FastSteps, ReferenceSteps, norm, square_sum

ARMS = [
    ("planar_3r", None),
    ("spatial_4r", None),
    ("powercube_3r", None),
    ("iiwa", None),
    ("iiwa", "pose"),
    ("panda", "position"),
    ("panda", "pose"),
    ("ur5", "position"),
    ("ur5", ("x", "y", "rz")),
    ("xarm7", "pose"),
]


def _load(name, task):
    return ft.load_arm(name) if task is None else ft.load_arm(name, task=task)


def _same(a, b) -> bool:
    return a.shape == b.shape and np.array_equal(a, b)


@pytest.mark.parametrize("name,task", ARMS)
def test_every_step_equals_the_reference_bit_for_bit(name, task):
    """Error, Jacobian, Newton step, null projector and K: equal at random configurations."""
    arm = _load(name, task)
    rng = np.random.default_rng(3)
    x0 = arm.fk(arm.random_q(rng))
    fast, ref = FastSteps(arm, x0), ReferenceSteps(arm, x0)
    sc = scenarios(arm.default_lockable, arm.n, r=max(arm.redundancy, 1), joint_names=arm.joint_names)
    jacs = []
    for _ in range(40):
        q = arm.random_q(rng)
        e_f, e_r = fast.error(q), ref.error(q)
        assert _same(e_f, e_r)
        J_f, J_r = fast.jacobian(q), ref.jacobian(q)
        assert _same(J_f, J_r)
        assert _same(fast.jacobian(q.copy()), J_r)  # another array: computed again, same numbers
        assert _same(fast.newton(J_f, e_f), ref.newton(J_r, e_r))
        assert _same(fast.null_projector(J_f), ref.null_projector(J_r))
        assert norm(e_f) == np.linalg.norm(e_r)
        assert norm(J_f[:, 0]) == np.linalg.norm(J_f[:, 0])  # a strided view, as numpy sums it
        jacs.append(J_f)
    if arm.redundancy >= 1:
        assert _same(fast.square_sums(jacs, sc), ref.square_sums(jacs, sc))


def test_damping_near_a_singularity_is_the_reference():
    """Near and at a singular J the Newton step is damped exactly as linalg.projection damps it."""
    arm = ft.load_arm("planar_3r")
    x0 = np.array([0.5, 0.1])
    fast, ref = FastSteps(arm, x0), ReferenceSteps(arm, x0)
    for eps in (0.0, 1e-9, 1e-6, 1e-4, 3e-3):
        q = np.array([0.2, eps, -eps])  # stretched out: σ_min(J) ~ eps
        J = fast.jacobian(q)
        assert projection(J).sigma_min < 10 * SIGMA_EPS
        step = fast.newton(J, fast.error(q))
        assert np.all(np.isfinite(step))
        assert _same(step, ref.newton(ref.jacobian(q), ref.error(q)))
        assert _same(fast.null_projector(J), ref.null_projector(J))


def test_batched_square_sums_with_multi_joint_scenarios():
    """K of many Jacobians at once, one-joint and multi-joint scenarios: equal to one by one."""
    arm = ft.load_arm("panda", task="position")
    rng = np.random.default_rng(5)
    jacs = [arm.jacobian(arm.random_q(rng)) for _ in range(25)]
    fast = FastSteps(arm, arm.fk(arm.q_reference))
    for lockable in (None, [(0, 1), 3, (2, 4, 6)]):
        sc = scenarios(lockable, arm.n, r=arm.redundancy)
        expected = np.array([square_sum(J, sc) for J in jacs])
        assert _same(fast.square_sums(jacs, sc), expected)
    assert fast.square_sums([], sc).shape == (0,)


def _assert_same_posture(a, b):
    assert _same(a.q, b.q) and a.K == b.K and a.method == b.method
    assert len(a.candidates) == len(b.candidates)
    for (ka, qa), (kb, qb) in zip(a.candidates, b.candidates, strict=True):
        assert ka == kb and _same(qa, qb)
    assert len(a.curves) == len(b.curves)
    for ca, cb, Ka, Kb in zip(a.curves, b.curves, a.curve_K, b.curve_K, strict=True):
        assert _same(ca, cb) and _same(Ka, Kb)


@pytest.mark.parametrize(
    "name,task,x0,lockable",
    [
        ("planar_3r", None, [0.40, 0.0], None),
        ("spatial_4r", None, [-0.21, 0.20, 0.35], ["joint1", "joint2", "joint3"]),
        ("powercube_3r", None, [0.50, 0.0], ["joint3"]),
    ],
)
def test_initial_posture_equals_the_reference_on_the_paper_arms(name, task, x0, lockable):
    """The whole search (curves, K along them, candidates, refined start): equal to the plain one."""
    arm = _load(name, task)
    kw = dict(seeds=6)
    fast = initial_posture(arm, np.array(x0), lockable, **kw)
    ref = initial_posture(arm, np.array(x0), lockable, reference=True, **kw)
    _assert_same_posture(fast, ref)


@pytest.mark.parametrize(
    "name,task",
    [("panda", "pose"), ("xarm7", "pose"), ("ur5", "position"), ("iiwa", "position")],
)
def test_initial_posture_equals_the_reference_on_other_arms(name, task):
    """r = 1 (a 7-joint pose task: curves) and r > 1 (descent): the same search, bit for bit."""
    arm = _load(name, task)
    rng = np.random.default_rng(1)
    q = arm.random_q(rng) * 0.5 + 0.5 * arm.q_reference
    x0 = arm.fk(q)
    kw = dict(starts=[q], step=0.05) if arm.redundancy == 1 else dict(starts=[q])
    fast = initial_posture(arm, x0, **kw)
    ref = initial_posture(arm, x0, reference=True, **kw)
    _assert_same_posture(fast, ref)
    np.testing.assert_allclose(arm.task_error(x0, fast.q), 0.0, atol=1e-8)


def test_public_steps_accept_reference_and_check_their_input():
    """inverse_kinematics and self_motion_curve: same answers either way; a wrong x0 is refused."""
    arm = ft.load_arm("planar_3r")
    x0, seed = np.array([0.35, 0.0]), np.array([0.5, 1.5, 1.0])
    q = inverse_kinematics(arm, x0, seed)
    assert _same(q, inverse_kinematics(arm, x0, seed, reference=True))
    pts, closed = self_motion_curve(arm, x0, q, step=0.05)
    pts_r, closed_r = self_motion_curve(arm, x0, q, step=0.05, reference=True)
    assert closed and closed_r and _same(pts, pts_r)
    with pytest.raises(ft.InvalidInput, match="x_des has shape"):
        inverse_kinematics(arm, [0.35, 0.0, 0.0], seed)
    with pytest.raises(ft.InvalidInput, match="x0 has shape"):
        self_motion_curve(arm, [0.35], q)
    with pytest.raises(ft.InvalidInput, match="shape"):
        inverse_kinematics(arm, x0, [0.1, 0.2])
