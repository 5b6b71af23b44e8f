"""The posture search's lean steps give the plain steps' numbers, bit for bit (posture_steps).

The golden-section refinement of the best curve point amplifies any rounding difference to
~1e-8 rad of the chosen start, so "close" is not enough: every step and the whole search are
compared for equality, on the shipped arms, on example-robot-data arms and on pose tasks.
"""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.linalg import SIGMA_EPS, projection
from fault_tolerance.planning.posture import initial_posture, inverse_kinematics, self_motion_curve
from fault_tolerance.planning.posture_steps import FastSteps, ReferenceSteps, norm, square_sum
from fault_tolerance.planning.wholepath.problem import kinematics
from fault_tolerance.resolution.scenarios import scenarios

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
    sc = scenarios(
        arm.default_lockable, arm.n, r=max(arm.redundancy, 1), joint_names=arm.joint_names
    )
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


# -- the whole-path planner's per-step kinematics (wholepath/problem.py) -----------------------


@pytest.mark.parametrize("name,task", ARMS)
def test_pinv_and_null_is_linalg_projection_bit_for_bit(name, task):
    """posture_steps.pinv_and_null: J⁺ and N of linalg.projection, regular and near-singular J."""
    from fault_tolerance.planning.posture_steps import pinv_and_null

    arm = _load(name, task)
    rng = np.random.default_rng(7)
    eye = np.eye(arm.n)
    Js = [arm.jacobian(arm.random_q(rng)) for _ in range(20)]
    Js.append(arm.jacobian(np.zeros(arm.n)))  # often stretched out or folded: damped
    Js.append(np.zeros((arm.m, arm.n)))  # rank 0: N = I
    for J in Js:
        P = projection(J)
        Jpinv, N = pinv_and_null(J, eye)
        assert _same(Jpinv, P.Jpinv) and _same(N, P.N)
        assert pinv_and_null(J, eye, False)[1] is None


def _post_rates_one_by_one(a, N, sc):
    """The per-scenario loop post_rates ran before it was vectorised (one-joint scenarios)."""
    from fault_tolerance.numerics.linalg import damped_pivots

    B, n = a.shape
    out = np.empty((B, sc.f, n))
    for s, (i,) in enumerate(sc.sets):
        piv = damped_pivots(N[:, i, i])
        out[:, s] = a - (a[:, i] / piv)[:, None] * N[:, :, i]
        out[:, s, i] = 0.0
    return out


@pytest.mark.parametrize(
    "name,task", [("spatial_4r", None), ("panda", "pose"), ("ur5", "position")]
)
def test_post_rates_of_all_scenarios_at_once_equal_one_by_one(name, task):
    """The vectorised one-joint post_rates: same numbers and C layout (einsum sums by layout)."""
    from fault_tolerance.planning.wholepath.problem import jumps, post_rates

    arm = _load(name, task)
    rng = np.random.default_rng(2)
    sc = scenarios(None, arm.n, r=arm.redundancy)
    J = np.array([arm.jacobian(arm.random_q(rng)) for _ in range(30)])
    N = projection(J).N
    N[0] = np.eye(arm.n) * 1e-6  # tiny pivots: damped
    a = rng.standard_normal((30, arm.n))
    got, ref = post_rates(a, N, sc), _post_rates_one_by_one(a, N, sc)
    assert _same(got, ref) and got.flags["C_CONTIGUOUS"]
    qd = rng.standard_normal((30, arm.n))
    assert _same(jumps(got, qd, sc.weights), jumps(ref, qd, sc.weights))


@pytest.mark.parametrize("gain", [0.0, 10.0])
def test_rollout_steps_are_the_plain_steps(gain):
    """rollout's rates equal a plain loop with linalg.projection (LNVA and JVJA), bit for bit."""
    from fault_tolerance.numerics.linalg import damped_pivots
    from fault_tolerance.paper.cases import CASES
    from fault_tolerance.planning.wholepath.problem import build_problem, rollout
    from fault_tolerance.resolution.jvja import jvja_rates

    case = CASES["fig7"]
    arm = ft.load_arm(case.robot)
    q0 = inverse_kinematics(arm, np.array(case.x0), np.array([0.2574, 1.2106, -0.9513, 1.9333]))
    prob = build_problem(
        arm, case.path(0.2), dt=0.002, steps=100, lockable=list(case.lockable),
        feedback_gain=gain, limits=False,
    )  # fmt: skip
    for mode in ("lnva", "jvja"):
        traj = rollout(prob, q0, mode)
        q = q0.copy()
        for k in range(prob.T + 1):
            xd = prob.xd_des[k] + (gain * arm.task_error(prob.x_des[k], q) if gain else 0.0)
            P = projection(arm.jacobian(q))
            a = P.Jpinv @ xd
            if mode == "jvja":
                piv = damped_pivots(prob.sc.pivots(P.N))
                a = jvja_rates(a, P.N, prob.sc, piv, damp=True)
            assert _same(traj.q[k], q) and _same(traj.qd[k], a)
            q = q + prob.dt * a


def test_batched_kinematics_is_the_arm_row_by_row():
    """wholepath kinematics: each row's J and task error equal the arm's (position and pose)."""
    from fault_tolerance.paper.cases import CASES
    from fault_tolerance.planning.wholepath.problem import build_problem

    for arm in (ft.load_arm("spatial_4r"), ft.load_arm("panda", task="pose")):
        path = CASES["fig7"].path(0.1)
        if arm.m == 6:
            from fault_tolerance.simulation.paths import CirclePath

            x0 = arm.fk(arm.q_reference)
            path = CirclePath(x0, 0.05, 2 * np.pi, 0.1, rows=(0, 1))
        prob = build_problem(arm, path, dt=0.01, steps=10, limits=False)
        rng = np.random.default_rng(4)
        Q = np.array([arm.random_q(rng) for _ in range(11)])
        J, E = kinematics(prob, Q, np.arange(11))
        for k, q in enumerate(Q):
            assert _same(J[k], arm.jacobian(q))
            if arm.m == 3:
                assert _same(E[k], arm.task_error(prob.x_des[k], q))
            else:  # scipy's rotation vector vs Pinocchio's log3: the same angle to rounding
                np.testing.assert_allclose(E[k], arm.task_error(prob.x_des[k], q), atol=1e-12)
