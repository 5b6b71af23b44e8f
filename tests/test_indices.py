"""indices: JVJ (1, 9, 10), RCN (15) and its gradient, δ (14), k_f and reduced manipulability."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.resolution import indices

ATOL = 1e-10
RTOL = 1e-9
H = 1e-6
FD_TOL = 1e-5


def _reduced(J, S):
    keep = [j for j in range(J.shape[1]) if j not in S]
    return J[:, keep]


def _explicit_post(J, xd, sets):
    """E_S J_S⁺ ẋ for every scenario from numpy's SVD pseudo-inverse, shape (f, n)."""
    out = []
    for S in sets:
        keep = [j for j in range(J.shape[1]) if j not in S]
        p = np.zeros(J.shape[1])
        p[keep] = np.linalg.pinv(J[:, keep]) @ xd
        out.append(p)
    return np.array(out)


# -- joint velocity jump (1), (9), (10) -----------------------------------------------------


def test_per_joint_jump_is_eq1(robot, rng, draw_q, draw_xdot):
    """Eq. (1): ˢλⱼ = |ˢq̇'ⱼ − q̇ⱼ| per scenario and joint; for j ∈ S it is |q̇ⱼ|."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    qd = ft.lnva(J, xd) + ft.nullspace_projector(J) @ rng.standard_normal(robot.n)
    lam = ft.jvj(J, xd, qd, list(robot.lockable), per_joint=True)
    sets = [(i,) for i in robot.lockable]
    expected = np.abs(_explicit_post(J, xd, sets) - qd)
    assert lam.shape == (len(sets), robot.n)
    np.testing.assert_allclose(lam, expected, rtol=RTOL, atol=ATOL)
    for k, (i,) in enumerate(sets):
        np.testing.assert_allclose(lam[k, i], abs(qd[i]), rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("weighted", [False, True])
def test_square_sum_jump_is_eq9_10(robot, rng, draw_q, draw_xdot, weighted):
    """Eq. (9)/(10): λ(q̇) = Σ_S w_S ‖ˢq̇' − q̇‖² with ˢq̇' = E_S J_S⁺ ẋ (incl. multi-joint S)."""
    sets = robot.sets
    q = draw_q(robot, rng, lockable=sets)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    w = rng.uniform(0.1, 2.0, len(sets)) if weighted else np.ones(len(sets))
    for qd in (ft.lnva(J, xd), ft.jvja(J, xd, sets, weights=w), rng.standard_normal(robot.n)):
        d = _explicit_post(J, xd, sets) - qd
        expected = float(w @ np.sum(d * d, axis=1))
        got = ft.jvj(J, xd, qd, sets, weights=w if weighted else None)
        np.testing.assert_allclose(got, expected, rtol=RTOL, atol=ATOL)


def test_continuation_jump_is_quadratic_form(panda_position, rng, draw_q, draw_xdot):
    """(G3) continuation jump of feasible rates: Σ_S w_S q̇[S]ᵀ N[S,S]⁻¹ q̇[S]."""
    case = panda_position
    sets = [(0,), (3,), (6,), (0, 1), (2, 3), (1, 4, 5), (0, 2, 4, 6)]
    q = draw_q(case, rng, lockable=sets)
    J = case.arm.jacobian(q)
    xd = draw_xdot(rng, case.m)
    N = ft.nullspace_projector(J)
    qd = ft.lnva(J, xd) + N @ rng.standard_normal(case.n)
    w = rng.uniform(0.1, 2.0, len(sets))
    expected = sum(
        wS * qd[list(S)] @ np.linalg.solve(N[np.ix_(S, S)], qd[list(S)])
        for S, wS in zip(sets, w, strict=True)
    )
    got = ft.jvj(J, xd, qd, sets, weights=w, response="continuation")
    np.testing.assert_allclose(got, expected, rtol=1e-8, atol=ATOL)


def test_jvj_is_zero_when_rates_are_the_reduced_rates_of_the_only_scenario(robot, rng, draw_q):
    """λ(ˢq̇') = 0 when S is the only scenario (the reduced robot keeps its rates)."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = rng.standard_normal(robot.m)
    for i in robot.lockable:
        qd = _explicit_post(J, xd, [(i,)])[0]
        np.testing.assert_allclose(ft.jvj(J, xd, qd, [i]), 0.0, atol=1e-18)


def test_jvj_rejects_unknown_response(planar_3r):
    """An unknown response model is refused with the allowed names."""
    J = planar_3r.arm.jacobian(np.array([0.3, 1.2, 1.0]))
    xd = np.array([0.1, 0.0])
    with pytest.raises(Exception, match="least_norm"):
        ft.jvj(J, xd, ft.lnva(J, xd), response="sideways")


# -- eq. (14) -------------------------------------------------------------------------------


@pytest.mark.parametrize("weighted", [False, True])
def test_jump_reduction_equals_prediction(robot, rng, draw_q, draw_xdot, weighted):
    """Eq. (14) at a shared configuration: δ = λ(q̇_LN) − λ(q̇_OPT) = (Σ w_S) ‖q̇_H‖² >= 0."""
    sets = robot.sets
    for _ in range(5):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        w = rng.uniform(0.1, 3.0, len(sets)) if weighted else None
        red = ft.jump_reduction(J, xd, sets, weights=w)
        scale = max(1.0, ft.jvj(J, xd, ft.lnva(J, xd), sets, weights=w))
        np.testing.assert_allclose(red.delta, red.predicted, rtol=0, atol=ATOL * scale)
        assert red.delta >= -ATOL * scale
        assert red.predicted >= 0.0
        np.testing.assert_allclose(
            red.qd_h, ft.jvja(J, xd, sets, weights=w) - ft.lnva(J, xd), atol=ATOL
        )
        # q̇_H lies in the null space
        np.testing.assert_allclose(J @ red.qd_h, 0.0, atol=ATOL)


def test_jump_reduction_unweighted_is_f_times_norm(robot, rng, draw_q, draw_xdot):
    """Unweighted eq. (14): predicted = f ‖q̇_H‖² with f the number of scenarios."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    red = ft.jump_reduction(J, xd, list(robot.lockable))
    f = len(robot.lockable)
    np.testing.assert_allclose(red.predicted, f * red.qd_h @ red.qd_h, rtol=1e-12, atol=0)


# -- reduced condition number (15) ----------------------------------------------------------


def test_rcn_equals_svd_condition_of_reduced_jacobian(robot, rng, draw_q):
    """Eq. (15): k_S = σ_max/σ_min of J with columns S removed (np.linalg.svd), and k_S >= 1."""
    sets = robot.sets
    for _ in range(5):
        J = robot.arm.jacobian(draw_q(robot, rng, lockable=sets))
        k = ft.rcn(J, sets)
        expected = []
        for S in sets:
            s = np.linalg.svd(_reduced(J, S), compute_uv=False)
            expected.append(s[0] / s[-1])
        np.testing.assert_allclose(k, expected, rtol=1e-8, atol=ATOL)
        assert np.all(k >= 1.0 - 1e-12)


def test_square_sum_rcn_is_sum_of_squares(robot, rng, draw_q):
    """K = Σ_S k_S²."""
    J = robot.arm.jacobian(draw_q(robot, rng))
    k = ft.rcn(J, list(robot.lockable))
    np.testing.assert_allclose(
        ft.square_sum_rcn(J, list(robot.lockable)), np.sum(k**2), rtol=1e-12, atol=ATOL
    )


def test_reduced_singular_values_match_svd(robot, rng, draw_q):
    """The batched eigvalsh of JJᵀ − J[:,S]J[:,S]ᵀ gives the singular values of each J_S."""
    sets = robot.sets
    J = robot.arm.jacobian(draw_q(robot, rng, lockable=sets))
    sc = ft.scenarios(sets, robot.n, r=robot.r)
    sig = indices.reduced_singular_values(J, sc)
    for S, s in zip(sets, sig, strict=True):
        np.testing.assert_allclose(
            s, np.sort(np.linalg.svd(_reduced(J, S), compute_uv=False)), rtol=1e-8, atol=ATOL
        )


def test_fault_tolerance_measure_is_min_reduced_sigma(robot, rng, draw_q):
    """k_f = min_S σ_min(J_S) (Roberts & Maciejewski), against explicit SVDs."""
    sets = robot.sets
    J = robot.arm.jacobian(draw_q(robot, rng, lockable=sets))
    expected = min(np.linalg.svd(_reduced(J, S), compute_uv=False)[-1] for S in sets)
    np.testing.assert_allclose(ft.fault_tolerance_measure(J, sets), expected, rtol=1e-8, atol=ATOL)


def test_reduced_manipulability_is_sqrt_det(robot, rng, draw_q):
    """w_S = √det(J_S J_Sᵀ), against numpy's det."""
    sets = robot.sets
    J = robot.arm.jacobian(draw_q(robot, rng, lockable=sets))
    expected = [np.sqrt(np.linalg.det(_reduced(J, S) @ _reduced(J, S).T)) for S in sets]
    np.testing.assert_allclose(ft.reduced_manipulability(J, sets), expected, rtol=1e-8, atol=ATOL)


def test_rcn_is_capped_at_a_rank_deficient_reduced_jacobian(planar_3r):
    """At the stretched planar 3R every J_S is rank-deficient: k_S is huge but finite."""
    J = planar_3r.arm.jacobian(np.zeros(3))
    k = ft.rcn(J)
    assert np.all(np.isfinite(k))
    assert np.all(k > 1e6)
    assert np.all(k <= indices.RCN_MAX)


# -- gradient of K --------------------------------------------------------------------------


def _fd_gradient(arm, q, lockable):
    eye = np.eye(arm.n)
    return np.array(
        [
            (
                ft.square_sum_rcn(arm.jacobian(q + H * eye[j]), lockable)
                - ft.square_sum_rcn(arm.jacobian(q - H * eye[j]), lockable)
            )
            / (2 * H)
            for j in range(arm.n)
        ]
    )


def test_rcn_gradient_matches_central_differences(robot, rng, draw_q):
    """∇K (singular-vector derivatives, kinematic Hessian) equals central differences of K."""
    sets = robot.sets
    for _ in range(3):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        grad = ft.rcn_gradient(J, robot.arm.jacobian_derivatives(q), sets)
        fd = _fd_gradient(robot.arm, q, sets)
        scale = max(1.0, np.abs(fd).max())
        np.testing.assert_allclose(grad, fd, rtol=0, atol=FD_TOL * scale)


def test_rcn_gradient_with_finite_difference_dJ(robot, rng, draw_q):
    """∇K is the same whether ∂J/∂q comes from the kinematic Hessian or central differences of J."""
    q = draw_q(robot, rng)
    arm = robot.arm
    eye = np.eye(arm.n)
    dJ_fd = np.array(
        [
            (arm.jacobian(q + H * eye[j]) - arm.jacobian(q - H * eye[j])) / (2 * H)
            for j in range(arm.n)
        ]
    )
    J = arm.jacobian(q)
    a = ft.rcn_gradient(J, arm.jacobian_derivatives(q), list(robot.lockable))
    b = ft.rcn_gradient(J, dJ_fd, list(robot.lockable))
    scale = max(1.0, np.abs(a).max())
    np.testing.assert_allclose(a, b, rtol=0, atol=FD_TOL * scale)
