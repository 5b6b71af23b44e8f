"""At and near singularities of J and of the reduced Jacobians: finite rates, flagged runs.

Configurations: the planar 3R outstretched (J singular) and with its last two links aligned
(locking joint1 leaves a singular J_S), the spatial 4R with its elbow straight or folded (J
singular), the Panda with its wrist aligned (q6 = 0: locking joint2 or joint6 leaves a singular
J_S). The identities of MATH.md at regular configurations are in test_properties.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fault_tolerance as ft
from fault_tolerance.numerics.linalg import (
    PIVOT_DAMPING,
    PIVOT_EPS,
    SIGMA_EPS,
    damped_pivots,
    projection,
)
from fault_tolerance.resolution.indices import RCN_MAX, post_failure_rates
from fault_tolerance.resolution.mda import MDA_MAX_STEP
from fault_tolerance.simulation.paths import CirclePath, FunctionPath
from fault_tolerance.simulation.run import (
    FLAG_NEAR_INTOLERABLE,
    FLAG_NEAR_SINGULAR,
    FLAG_OVER_SPEED,
    FLAG_STEP_LIMITED,
)
from fault_tolerance.simulation.simulate import simulate

PROPS = settings(max_examples=25, deadline=None, derandomize=True, database=None)
ALGS = ("lnva", "jvja", "mda")


def panda_wrist_aligned(arm: ft.Arm) -> np.ndarray:
    """The Panda's reference posture with q6 = 0 (axes of joints 5 and 7 parallel)."""
    q = arm.q_reference.copy()
    q[5] = 0.0
    return q


#: name -> (robot fixture, configuration (or a function of the arm), lockable, what is singular)
SINGULAR = {
    "3r_outstretched": ("planar_3r", [0.3, 0.0, 0.0], (0, 1, 2), "J"),
    "3r_links_2_3_aligned": ("planar_3r", [0.3, 1.0, 0.0], (0, 1, 2), "J_S"),
    "4r_elbow_straight": ("spatial_4r", [0.3, 0.5, 0.2, 0.0], (0, 1, 2), "J"),
    "4r_elbow_folded": ("spatial_4r", [0.3, 0.5, 0.2, np.pi], (0, 1, 2), "J"),
    "panda_wrist_aligned": ("panda_pose", panda_wrist_aligned, (0, 1, 2, 4, 5, 6), "J_S"),
}


@pytest.fixture(params=sorted(SINGULAR))
def singular(request):
    """(name, arm, q, lockable, kind) for each singular configuration."""
    fixture, q, lockable, kind = SINGULAR[request.param]
    arm = request.getfixturevalue(fixture).arm
    q = np.asarray(q(arm) if callable(q) else q, dtype=float)
    return request.param, arm, q, list(lockable), kind


def rates(alg: str, arm: ft.Arm, q: np.ndarray, xd: np.ndarray, lockable) -> np.ndarray:
    """The resolver's rates as the simulation asks for them (near-intolerable pivots damped)."""
    return ft.resolve(alg, arm.jacobian(q), xd, lockable, arm=arm, q=q, tolerate=True)


def check_rates(alg: str, J: np.ndarray, xd: np.ndarray, qd: np.ndarray) -> None:
    """Finite rates, task error no larger than ‖ẋ‖, and the bound each resolver guarantees.

    LNVA: ‖J⁺ẋ‖ ≤ ‖ẋ‖ / SIGMA_EPS (variable damping). JVJA: the damped pivots add at most
    ‖N eᵢ‖ |aᵢ| / p_eff ≤ |aᵢ| / √PIVOT_EPS per scenario. MDA: at most MDA_MAX_STEP.
    """
    assert np.all(np.isfinite(qd))
    a = projection(J).Jpinv @ xd
    bound_a = np.linalg.norm(xd) / SIGMA_EPS * (1 + 1e-9)
    assert np.linalg.norm(a) <= bound_a
    assert np.linalg.norm(J @ qd - xd) <= np.linalg.norm(xd) * (1 + 1e-6) + 1e-9
    extra = {
        "lnva": 1e-12,
        "jvja": np.abs(a).max() / np.sqrt(PIVOT_EPS) * (1 + 1e-9),
        "mda": MDA_MAX_STEP * (1 + 1e-9),
    }[alg]
    assert np.linalg.norm(qd - a) <= extra + 1e-12


def test_configurations_are_singular_as_claimed(singular):
    """The test configurations are what they claim: σ_min(J) ≈ 0, or a pivot of N[S, S] ≈ 0."""
    name, arm, q, lockable, kind = singular
    proj = projection(arm.jacobian(q))
    if kind == "J":
        assert proj.sigma_min < 1e-8 and proj.damped
    else:
        assert proj.sigma_min > SIGMA_EPS
        sc = ft.scenarios(lockable, arm.n, r=arm.redundancy)
        assert sc.pivots(proj.N).min() < 1e-9


@pytest.mark.parametrize("alg", ALGS)
def test_rates_at_singular_configurations_are_finite_and_bounded(singular, alg, rng):
    """At a singular J or J_S every resolver returns finite rates within its bound."""
    name, arm, q, lockable, kind = singular
    J = arm.jacobian(q)
    for _ in range(3):
        xd = rng.standard_normal(arm.m)
        check_rates(alg, J, xd, rates(alg, arm, q, xd, lockable))


def test_exactly_intolerable_configuration_is_named_unless_tolerated(singular, rng):
    """Where J_S is singular, JVJA without tolerate raises IntolerableFailure naming the joint;
    indices stay finite (RCN capped at RCN_MAX, damped reduced rates)."""
    name, arm, q, lockable, kind = singular
    J = arm.jacobian(q)
    xd = rng.standard_normal(arm.m)
    k = ft.rcn(J, lockable)
    assert np.all(np.isfinite(k)) and np.all((k >= 1) & (k <= RCN_MAX))
    proj = projection(J)
    sc = ft.scenarios(lockable, arm.n, r=arm.redundancy, joint_names=arm.joint_names)
    post = post_failure_rates(proj.Jpinv @ xd, proj.N, sc, damp=True)
    assert np.all(np.isfinite(post))
    if kind == "J_S":
        with pytest.raises(ft.IntolerableFailure) as err:
            ft.resolve("jvja", J, xd, lockable, joint_names=arm.joint_names)
        assert err.value.joints[0] in arm.joint_names and err.value.pivot < 1e-9


@PROPS
@given(
    log_eps=st.floats(-12.0, -1.0),
    seed=st.integers(0, 2**32 - 1),
    alg=st.sampled_from(ALGS),
    which=st.sampled_from(sorted(SINGULAR)),
)
def test_rates_near_singular_configurations_are_finite_and_bounded(
    request, log_eps, seed, alg, which
):
    """Property: at q_sing + ε d (ε from 1e-12 to 0.1, d random unit) every resolver's rates are
    finite and within its bound, and the reduced condition numbers finite in [1, RCN_MAX]."""
    fixture, q, lockable, _ = SINGULAR[which]
    arm = request.getfixturevalue(fixture).arm
    q = np.asarray(q(arm) if callable(q) else q, dtype=float)
    rng = np.random.default_rng(seed)
    d = rng.standard_normal(arm.n)
    q = q + 10.0**log_eps * d / np.linalg.norm(d)
    xd = rng.standard_normal(arm.m)
    J = arm.jacobian(q)
    check_rates(alg, J, xd, rates(alg, arm, q, xd, list(lockable)))
    k = ft.rcn(J, list(lockable))
    assert np.all(np.isfinite(k)) and np.all((k >= 1) & (k <= RCN_MAX))


@PROPS
@given(seed=st.integers(0, 2**32 - 1))
def test_damping_leaves_regular_configurations_alone(robot, seed):
    """Property: where every pivot is ≥ PIVOT_EPS, JVJA with tolerate equals JVJA without."""
    from conftest import random_well_conditioned_q, random_xdot

    rng = np.random.default_rng(seed)
    q = random_well_conditioned_q(robot.arm, rng, robot.lockable)
    J = robot.arm.jacobian(q)
    xd = random_xdot(rng, robot.m)
    for response in ("least_norm", "continuation"):
        np.testing.assert_array_equal(
            ft.jvja(J, xd, list(robot.lockable), response=response, tolerate=True),
            ft.jvja(J, xd, list(robot.lockable), response=response),
        )


@PROPS
@given(p=st.floats(0.0, 1.0))
def test_damped_pivots_are_bounded_below_and_exact_above_the_threshold(p):
    """Property: damped pivots are ≥ PIVOT_DAMPING², equal p from PIVOT_EPS on, and √p / p_eff
    (the gain of a scenario's term in JVJA) stays ≤ 1/√PIVOT_EPS."""
    pe = float(damped_pivots(p))
    assert pe >= PIVOT_DAMPING**2 * (1 - 1e-12)
    if p >= PIVOT_EPS:
        assert pe == p
    assert np.sqrt(p) / pe <= 1 / np.sqrt(PIVOT_EPS) * (1 + 1e-9)
    assert abs(float(damped_pivots(PIVOT_EPS * (1 - 1e-12))) - PIVOT_EPS) < 1e-15  # continuous


# -- runs ---------------------------------------------------------------------------------------


def finite_run(run) -> bool:
    """Every recorded array is finite."""
    return all(
        np.all(np.isfinite(getattr(run, k)))
        for k in ("q", "qd", "x", "error", "jvj", "jvj_parts", "rcn", "K", "sigma_min")
    )


@pytest.mark.parametrize("alg", ALGS)
def test_run_past_the_edge_of_the_workspace_is_finite_and_flagged(planar_3r, alg):
    """A circle leaving the planar 3R's workspace: the run completes with finite histories and
    says where it was singular, near-intolerable, too fast or step-limited."""
    arm = planar_3r.arm
    q0 = np.array([0.05, -0.1, 0.08])  # 1.4985 m out of 1.5 m
    path = CirclePath(arm.fk(q0), 0.1, 2 * np.pi, 0.3, rows=(0, 1))  # moves outwards
    run = simulate(arm, path, alg, q0=q0, lockable=[0, 1, 2])
    assert finite_run(run)
    s = run.summary()
    flagged = FLAG_NEAR_SINGULAR | FLAG_NEAR_INTOLERABLE | FLAG_OVER_SPEED | FLAG_STEP_LIMITED
    assert np.count_nonzero(run.flags & flagged) > 0
    if alg == "lnva":
        assert s["near_singular_samples"] > 0
        assert np.all(run.sigma_min[run.flags & FLAG_NEAR_SINGULAR > 0] < SIGMA_EPS)
    assert s["over_speed_samples"] == np.count_nonzero(
        np.any(
            np.abs(run.qd_cmd if run.qd_cmd is not None else run.qd) > arm.velocity_limit, axis=1
        )
    )


@pytest.mark.parametrize("alg", ["lnva", "jvja"])
def test_run_through_a_reduced_singularity_is_finite_and_flagged(planar_3r, alg):
    """A path along which links 2 and 3 come into line (J_S singular for joint1 locked) runs to
    the end: finite rates and jump index, FLAG_NEAR_INTOLERABLE where the pivot is small, JVJA's
    rates bounded by the pivot damping."""
    arm = planar_3r.arm
    qa, v = np.array([0.3, 1.0, 0.15]), np.array([0.2, -0.3, -0.5])  # q3 crosses 0 at t = 0.3 s
    path = FunctionPath(lambda t: arm.fk(qa + t * v), 0.6, lambda t: arm.jacobian(qa + t * v) @ v)
    run = simulate(arm, path, alg, q0=qa, lockable=["joint1"])
    assert finite_run(run)
    pivots = np.array([projection(arm.jacobian(q)).N[0, 0] for q in run.q])
    near = (run.flags & FLAG_NEAR_INTOLERABLE) > 0
    np.testing.assert_array_equal(near, pivots < PIVOT_EPS)
    assert near.any() and pivots.min() < 1e-4
    assert np.abs(run.qd).max() < 50.0
    assert run.error.max() < 1e-2


def test_run_through_the_4r_elbow_singularity_is_finite_and_flagged(spatial_4r):
    """The 4R's elbow straightening on the way (J singular): finite, flagged near-singular."""
    arm = spatial_4r.arm
    qa, v = np.array([0.3, 0.5, 0.2, 0.3]), np.array([0.1, 0.0, 0.2, -1.0])  # q4 = 0 at 0.3 s
    path = FunctionPath(lambda t: arm.fk(qa + t * v), 0.5, lambda t: arm.jacobian(qa + t * v) @ v)
    for alg in ALGS:
        run = simulate(arm, path, alg, q0=qa, lockable=[0, 1, 2])
        assert finite_run(run), alg
        assert run.summary()["near_singular_samples"] > 0, alg


def test_mda_from_a_poor_start_is_step_limited_not_lost(planar_3r):
    """MDA started far from the minimum-RCN posture (‖α N ∇K‖ ~ 10⁴ rad/s): the null-space step
    is capped per time step and flagged, and the tool stays on the path (no Euler blow-up)."""
    arm = planar_3r.arm
    q0 = np.array([0.05, -0.1, 0.08])
    path = CirclePath(arm.fk(q0), 0.1, 2 * np.pi, 0.1, rows=(0, 1), sign=-1.0)  # inwards
    run = simulate(arm, path, "mda", q0=q0, lockable=[0, 1, 2], limits=False)  # the paper's MDA
    assert finite_run(run)
    assert run.summary()["step_limited_samples"] > 0
    assert run.error.max() < 1e-2
    assert run.flags[0] & FLAG_STEP_LIMITED


def test_lock_near_a_singularity_keeps_the_reduced_robot_finite(planar_3r):
    """Locking joint1 where links 2 and 3 are nearly in line (σ_min of the remaining columns below
    SIGMA_EPS): the reduced robot's rates are damped, finite, and those samples flagged."""
    arm = planar_3r.arm
    q0 = np.array([0.3, 1.0, 5e-4])
    path = CirclePath(arm.fk(q0), 0.05, 2 * np.pi, 0.1, rows=(0, 1))
    run = simulate(
        arm, path, "lnva", q0=q0, lockable=["joint2"], lock_joint="joint1", lock_time=0.0
    )
    assert finite_run(run)
    assert np.all(run.qd[:, 0] == 0.0)
    assert run.flags[0] & FLAG_NEAR_SINGULAR
