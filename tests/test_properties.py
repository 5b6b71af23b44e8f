"""Property-based tests (hypothesis) of MATH.md's identities over random configurations.

Every shipped arm and the Panda (pose r = 1, position r = 4). Configurations that the identities
need to be well-conditioned come from a hypothesis-drawn seed and the rejection sampler of
conftest (so every example is reproducible); derivative checks that hold everywhere draw the joint
angles directly. Hypothesis is derandomized and keeps no example database.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import fault_tolerance as ft
from fault_tolerance.numerics import linalg

ATOL = 1e-10
RTOL = 1e-9
H = 1e-6
FD_TOL = 1e-5

PROPS = settings(max_examples=30, deadline=None, derandomize=True, database=None)

seeds = st.integers(min_value=0, max_value=2**32 - 1)
xdots = st.lists(
    st.floats(-1.0, 1.0, allow_nan=False, allow_subnormal=False), min_size=6, max_size=6
).map(np.array)
weight_lists = st.lists(st.floats(0.05, 5.0, allow_nan=False), min_size=16, max_size=16).map(
    np.array
)
unit = st.floats(0.0, 1.0, allow_nan=False, allow_subnormal=False)
fractions = st.lists(unit, min_size=7, max_size=7).map(np.array)


def _setup(case, seed, draw_q, sets=None):
    """A well-conditioned configuration drawn from ``seed``, its Jacobian and projection."""
    rng = np.random.default_rng(seed)
    q = draw_q(case, rng, lockable=case.sets if sets is None else sets)
    J = case.arm.jacobian(q)
    return rng, q, J, ft.projection(J)


def _q_from_fractions(arm, frac):
    """A configuration anywhere within the joint limits (fractions in [0, 1] of each range)."""
    return arm.lower + frac[: arm.n] * (arm.upper - arm.lower)


@PROPS
@given(seed=seeds, xd6=xdots, w=weight_lists)
def test_every_resolver_satisfies_the_task(robot, draw_q, seed, xd6, w):
    """J q̇ = ẋ for LNVA, JVJA (both responses, weighted, multi-joint when r > 1) and MDA."""
    rng, q, J, _ = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    sets = robot.sets
    wS = w[: len(sets)]
    for qd in (
        ft.resolve("lnva", J, xd),
        ft.resolve("jvja", J, xd, sets),
        ft.resolve("jvja", J, xd, sets, weights=wS),
        ft.resolve("jvja", J, xd, sets, weights=wS, response="continuation"),
        ft.resolve("mda", J, xd, sets, arm=robot.arm, q=q),
        ft.resolve("mda", J, xd, sets, arm=robot.arm, q=q, gain=1.0),
    ):
        # rounding of J q̇ grows with ‖q̇‖ (MDA's N∇K can be large near low dexterity)
        np.testing.assert_allclose(J @ qd, xd, atol=ATOL * max(1.0, np.linalg.norm(qd)))


@PROPS
@given(seed=seeds)
def test_projector_and_pseudo_inverse_identities(robot, draw_q, seed):
    """N = Nᵀ = N², J N = 0, J⁺ = Jᵀ(JJᵀ)⁻¹ away from singularities."""
    _, _, J, proj = _setup(robot, seed, draw_q)
    N = proj.N
    np.testing.assert_allclose(N, N.T, atol=ATOL)
    np.testing.assert_allclose(N @ N, N, atol=ATOL)
    np.testing.assert_allclose(J @ N, 0.0, atol=ATOL)
    np.testing.assert_allclose(proj.Jpinv, J.T @ np.linalg.inv(J @ J.T), rtol=RTOL, atol=ATOL)


@PROPS
@given(seed=seeds, xd6=xdots)
def test_closed_form_reduced_rates_equal_explicit(robot, draw_q, seed, xd6):
    """(G1) = eq. (2): a − N[:,S] N[S,S]⁻¹ a[S] = E_S J_S⁺ ẋ for every scenario (|S| <= r)."""
    _, _, J, proj = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    a = proj.Jpinv @ xd
    for S in robot.sets:
        np.testing.assert_allclose(
            ft.reduced_rates(a, proj.N, S),
            linalg.reduced_rates_explicit(J, xd, S),
            rtol=RTOL,
            atol=ATOL,
        )


@PROPS
@given(seed=seeds, xd6=xdots, w=weight_lists, weighted=st.booleans())
def test_jvja_closed_form_equals_explicit(robot, draw_q, seed, xd6, w, weighted):
    """Eq. (5): JVJA's closed form equals J⁺ẋ + N · mean_w(E_S J_S⁺ ẋ) (weighted, multi-joint)."""
    _, _, J, _ = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    sets = robot.sets
    wS = w[: len(sets)] if weighted else None
    np.testing.assert_allclose(
        ft.jvja(J, xd, sets, weights=wS),
        ft.jvja_explicit(J, xd, sets, weights=wS),
        rtol=RTOL,
        atol=ATOL,
    )


@PROPS
@given(seed=seeds, xd6=xdots, w=weight_lists, weighted=st.booleans())
def test_jump_reduction_identity(robot, draw_q, seed, xd6, w, weighted):
    """Eq. (14) at a shared configuration: δ = (Σ w_S) ‖q̇_H‖² >= 0."""
    _, _, J, _ = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    sets = robot.sets
    wS = w[: len(sets)] if weighted else None
    red = ft.jump_reduction(J, xd, sets, weights=wS)
    scale = max(1.0, ft.jvj(J, xd, ft.lnva(J, xd), sets, weights=wS))
    np.testing.assert_allclose(red.delta, red.predicted, rtol=0, atol=ATOL * scale)
    assert red.delta >= -ATOL * scale


@PROPS
@given(seed=seeds, xd6=xdots, gain=st.floats(0.0, 2.0))
def test_jvja_jump_is_minimal(robot, draw_q, seed, xd6, gain):
    """λ(JVJA) <= λ(LNVA) and λ(JVJA) <= λ(MDA) at the same configuration."""
    _, q, J, _ = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    sets = robot.sets
    best = ft.jvj(J, xd, ft.jvja(J, xd, sets), sets)
    tol = ATOL * max(1.0, best)
    assert best <= ft.jvj(J, xd, ft.lnva(J, xd), sets) + tol
    assert best <= ft.jvj(J, xd, ft.mda(J, xd, sets, arm=robot.arm, q=q, gain=gain), sets) + tol


@PROPS
@given(seed=seeds, xd6=xdots, k_pick=unit, response=st.sampled_from(["least_norm", "continuation"]))
def test_single_lockable_joint_is_held_still(robot, draw_q, seed, xd6, k_pick, response):
    """Eq. (8): with one lockable joint k, JVJA's q̇ₖ is 0 and the jump is 0."""
    k = robot.lockable[min(int(k_pick * len(robot.lockable)), len(robot.lockable) - 1)]
    _, _, J, _ = _setup(robot, seed, draw_q, sets=[(k,)])
    xd = xd6[: robot.m]
    qd = ft.jvja(J, xd, [k], response=response)
    np.testing.assert_allclose(qd[k], 0.0, atol=1e-12)
    np.testing.assert_allclose(ft.jvj(J, xd, qd, [k], response=response), 0.0, atol=1e-12)


@PROPS
@given(seed=seeds, xd6=xdots, w=weight_lists, z=st.lists(st.floats(-3, 3), min_size=7, max_size=7))
def test_g3_responses(robot, draw_q, seed, xd6, w, z):
    """(G3): r = 1 both responses coincide; r > 1 the continuation jump is never larger."""
    _, _, J, proj = _setup(robot, seed, draw_q)
    xd = xd6[: robot.m]
    sets = robot.sets
    wS = w[: len(sets)]
    qd = proj.Jpinv @ xd + proj.N @ np.array(z[: robot.n])  # any rates with J q̇ = ẋ
    lam_ln = ft.jvj(J, xd, qd, sets, weights=wS)
    lam_co = ft.jvj(J, xd, qd, sets, weights=wS, response="continuation")
    opt_ln = ft.jvja(J, xd, sets, weights=wS)
    opt_co = ft.jvja(J, xd, sets, weights=wS, response="continuation")
    best_ln = ft.jvj(J, xd, opt_ln, sets, weights=wS)
    best_co = ft.jvj(J, xd, opt_co, sets, weights=wS, response="continuation")
    if robot.r == 1:
        np.testing.assert_allclose(lam_co, lam_ln, rtol=1e-8, atol=ATOL)
        np.testing.assert_allclose(opt_co, opt_ln, rtol=1e-8, atol=ATOL)
    else:
        assert lam_co <= lam_ln + ATOL * max(1.0, lam_ln)
        assert best_co <= best_ln + ATOL * max(1.0, best_ln)
        assert best_co <= lam_co + ATOL * max(1.0, lam_co)  # the continuation optimum


@PROPS
@given(seed=seeds)
def test_rcn_identities(robot, draw_q, seed):
    """Eq. (15): k_S = σ_max/σ_min of J without columns S, k_S >= 1, K = Σ k_S²."""
    _, _, J, _ = _setup(robot, seed, draw_q)
    sets = robot.sets
    k = ft.rcn(J, sets)
    expected = []
    for S in sets:
        keep = [j for j in range(robot.n) if j not in S]
        s = np.linalg.svd(J[:, keep], compute_uv=False)
        expected.append(s[0] / s[-1])
    np.testing.assert_allclose(k, expected, rtol=1e-8, atol=ATOL)
    assert np.all(k >= 1.0 - 1e-12)
    np.testing.assert_allclose(ft.square_sum_rcn(J, sets), np.sum(k**2), rtol=1e-12)


@PROPS
@given(seed=seeds)
def test_rcn_gradient_is_derivative_of_k(robot, draw_q, seed):
    """∇K (singular-vector formula, kinematic Hessian) equals central differences of K(q)."""
    _, q, J, _ = _setup(robot, seed, draw_q)
    arm, sets = robot.arm, robot.sets
    grad = ft.rcn_gradient(J, arm.jacobian_derivatives(q), sets)
    eye = np.eye(arm.n)
    fd = np.array(
        [
            (
                ft.square_sum_rcn(arm.jacobian(q + H * eye[j]), sets)
                - ft.square_sum_rcn(arm.jacobian(q - H * eye[j]), sets)
            )
            / (2 * H)
            for j in range(arm.n)
        ]
    )
    np.testing.assert_allclose(grad, fd, rtol=0, atol=FD_TOL * max(1.0, np.abs(fd).max()))


@PROPS
@given(frac=fractions)
def test_jacobian_and_its_derivatives_match_finite_differences(robot, frac):
    """Anywhere in the limits: linear rows of J = ∂fk/∂q, angular rows from log3, ∂J/∂q = dJ."""
    arm = robot.arm
    q = _q_from_fractions(arm, frac)
    eye = np.eye(arm.n)
    J = arm.jacobian(q)
    dJ = arm.jacobian_derivatives(q)
    for j in range(arm.n):
        qp, qm = q + H * eye[j], q - H * eye[j]
        Mp, Mm = arm.placement(qp), arm.placement(qm)
        col = np.concatenate(
            [(Mp.translation - Mm.translation), pin.log3(Mp.rotation @ Mm.rotation.T)]
        ) / (2 * H)
        np.testing.assert_allclose(J[:, j], col[arm.rows], atol=FD_TOL)
        np.testing.assert_allclose(
            dJ[j], (arm.jacobian(qp) - arm.jacobian(qm)) / (2 * H), atol=FD_TOL
        )


@PROPS
@given(frac=fractions)
def test_spatial_4r_joint4_is_intolerable_everywhere(spatial_4r, frac):
    """The 4R's joint4 cannot lock at any full-rank configuration: IntolerableFailure names it."""
    arm = spatial_4r.arm
    q = _q_from_fractions(arm, frac)
    J = arm.jacobian(q)
    assume(np.linalg.svd(J, compute_uv=False)[-1] > 1e-2)  # at a singularity N says nothing
    np.testing.assert_allclose(ft.nullspace_projector(J)[3, 3], 0.0, atol=1e-10)
    with pytest.raises(ft.IntolerableFailure, match="joint4"):
        ft.resolve("jvja", J, np.array([0.0, 0.1, 0.2]), lockable=[3], joint_names=arm.joint_names)
