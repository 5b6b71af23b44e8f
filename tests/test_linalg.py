"""linalg: pseudo-inverse, null-space projector, closed-form reduced rates (MATH (2), G1, G3)."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics import linalg

ATOL = 1e-10  # algebraic identities
RTOL = 1e-9


def test_pinv_equals_normal_equations_and_numpy(robot, rng, draw_q):
    """Away from singularities J⁺ = Jᵀ(JJᵀ)⁻¹ = numpy's SVD pseudo-inverse and J J⁺ = I."""
    for _ in range(5):
        J = robot.arm.jacobian(draw_q(robot, rng))
        Jp = ft.pinv(J)
        np.testing.assert_allclose(Jp, J.T @ np.linalg.inv(J @ J.T), rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(Jp, np.linalg.pinv(J), rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(J @ Jp, np.eye(robot.m), atol=ATOL)


def test_projector_symmetric_idempotent_and_annihilated_by_J(robot, rng, draw_q):
    """N is symmetric, idempotent, J N = 0, N = I − J⁺J and its trace is r."""
    for _ in range(5):
        J = robot.arm.jacobian(draw_q(robot, rng))
        N = ft.nullspace_projector(J)
        np.testing.assert_allclose(N, N.T, atol=ATOL)
        np.testing.assert_allclose(N @ N, N, atol=ATOL)
        np.testing.assert_allclose(J @ N, 0.0, atol=ATOL)
        np.testing.assert_allclose(N, np.eye(robot.n) - ft.pinv(J) @ J, atol=ATOL)
        np.testing.assert_allclose(np.trace(N), robot.r, atol=ATOL)


def test_projection_reports_sigma_min_and_no_damping(robot, rng, draw_q):
    """projection() returns σ_min(J) from the SVD and does not damp a well-conditioned J."""
    J = robot.arm.jacobian(draw_q(robot, rng))
    proj = ft.projection(J)
    np.testing.assert_allclose(proj.sigma_min, np.linalg.svd(J, compute_uv=False)[-1], rtol=1e-9)
    assert not proj.damped


def test_reduced_rates_closed_form_equals_explicit_pinv(robot, rng, draw_q, draw_xdot):
    """Eq. (2) in closed form (G1): a − N[:,S] N[S,S]⁻¹ a[S] equals E_S J_S⁺ ẋ (|S| <= r)."""
    sets = robot.sets
    for _ in range(5):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        proj = ft.projection(J)
        a = proj.Jpinv @ xd
        for S in sets:
            fast = ft.reduced_rates(a, proj.N, S)
            slow = linalg.reduced_rates_explicit(J, xd, S)
            np.testing.assert_allclose(fast, slow, rtol=RTOL, atol=ATOL)


def test_reduced_rates_zero_at_locked_joints_and_track_task(robot, rng, draw_q, draw_xdot):
    """Reduced rates are exactly 0 at the locked joints and still satisfy J ˢq̇' = ẋ."""
    sets = robot.sets
    q = draw_q(robot, rng, lockable=sets)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    proj = ft.projection(J)
    a = proj.Jpinv @ xd
    for S in sets:
        qd = ft.reduced_rates(a, proj.N, S)
        assert np.all(qd[list(S)] == 0.0)
        np.testing.assert_allclose(J @ qd, xd, atol=ATOL)


def test_single_joint_formula(robot, rng, draw_q, draw_xdot):
    """(G1) for one joint: ⁱq̇' = a − (aᵢ/Nᵢᵢ) N eᵢ, the same as the general N[S,S]⁻¹ solve."""
    J = robot.arm.jacobian(draw_q(robot, rng))
    xd = draw_xdot(rng, robot.m)
    proj = ft.projection(J)
    a, N = proj.Jpinv @ xd, proj.N
    for i in robot.lockable:
        expected = a - (a[i] / N[i, i]) * N[:, i]
        general = a - N[:, [i]] @ np.linalg.solve(N[np.ix_([i], [i])], a[[i]])
        np.testing.assert_allclose(ft.reduced_rates(a, N, [i]), expected, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(expected, general, rtol=RTOL, atol=ATOL)


def _nearest_solution(J, xd, qd, S):
    """Explicit reference: the rates nearest to qd with J v = ẋ and v[S] = 0."""
    n = J.shape[1]
    E = np.eye(n)[list(S)]
    A = np.vstack([J, E])
    b = np.concatenate([xd, np.zeros(len(S))])
    return qd + np.linalg.pinv(A) @ (b - A @ qd)


def test_continuation_rates_are_nearest_solution(robot, rng, draw_q, draw_xdot):
    """(G3) ˢq̇'' = q̇ − N[:,S] N[S,S]⁻¹ q̇[S] is the solution of the reduced robot nearest to q̇."""
    sets = robot.sets
    q = draw_q(robot, rng, lockable=sets)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    proj = ft.projection(J)
    qd = proj.Jpinv @ xd + proj.N @ rng.standard_normal(robot.n)  # any rates with J q̇ = ẋ
    for S in sets:
        cont = linalg.continuation_rates(qd, proj.N, S)
        np.testing.assert_allclose(cont, _nearest_solution(J, xd, qd, S), rtol=RTOL, atol=ATOL)
        # and its jump is the quadratic form q̇[S]ᵀ N[S,S]⁻¹ q̇[S]
        s = list(S)
        quad = qd[s] @ np.linalg.solve(proj.N[np.ix_(s, s)], qd[s])
        np.testing.assert_allclose(np.sum((cont - qd) ** 2), quad, rtol=1e-8, atol=ATOL)


def test_continuation_equals_least_norm_response_when_r_is_1(r1_robot, rng, draw_q, draw_xdot):
    """For r = 1 the reduced rates are forced: ˢq̇'' = ˢq̇' whatever the rates q̇ before the lock."""
    robot = r1_robot
    assert robot.r == 1
    J = robot.arm.jacobian(draw_q(robot, rng))
    xd = draw_xdot(rng, robot.m)
    proj = ft.projection(J)
    a = proj.Jpinv @ xd
    qd = a + proj.N @ rng.standard_normal(robot.n)
    for i in robot.lockable:
        np.testing.assert_allclose(
            linalg.continuation_rates(qd, proj.N, [i]),
            ft.reduced_rates(a, proj.N, [i]),
            rtol=RTOL,
            atol=ATOL,
        )


def test_min_pivot_is_smallest_eigenvalue(panda_position, rng, draw_q):
    """min_pivot(N, S) is the smallest eigenvalue of N[S, S] (the diagonal entry for one joint)."""
    N = ft.nullspace_projector(panda_position.arm.jacobian(draw_q(panda_position, rng)))
    for S in [(0,), (3,), (0, 1), (2, 3, 5), (0, 2, 4, 6)]:
        s = list(S)
        np.testing.assert_allclose(
            linalg.min_pivot(N, S), np.linalg.eigvalsh(N[np.ix_(s, s)])[0], atol=ATOL
        )


def test_projection_at_a_singularity_is_damped_and_finite(planar_3r):
    """At the stretched planar 3R (rank 1) J⁺ is damped and finite; N projects on the 2-D kernel."""
    J = planar_3r.arm.jacobian(np.zeros(3))
    proj = ft.projection(J)
    assert proj.damped
    assert proj.sigma_min < linalg.SIGMA_EPS
    assert np.all(np.isfinite(proj.Jpinv))
    N = proj.N
    np.testing.assert_allclose(N, N.T, atol=ATOL)
    np.testing.assert_allclose(N @ N, N, atol=ATOL)
    np.testing.assert_allclose(J @ N, 0.0, atol=ATOL)
    np.testing.assert_allclose(np.trace(N), 2.0, atol=ATOL)
    # damped least squares: J⁺ = Jᵀ (JJᵀ + μ² I)⁻¹ with μ² = DAMPING² at σ_min = 0
    mu2 = linalg.damping_factor(proj.sigma_min)
    np.testing.assert_allclose(
        proj.Jpinv, J.T @ np.linalg.inv(J @ J.T + mu2 * np.eye(2)), rtol=1e-8, atol=ATOL
    )


def test_damping_factor_is_continuous_and_bounded():
    """μ² is DAMPING² at σ_min = 0, decreases to 0 at SIGMA_EPS and stays 0 above it."""
    eps, d = linalg.SIGMA_EPS, linalg.DAMPING
    np.testing.assert_allclose(linalg.damping_factor(0.0), d**2, atol=1e-15)
    np.testing.assert_allclose(linalg.damping_factor(eps * (1 - 1e-9)), 0.0, atol=1e-12)
    assert linalg.damping_factor(eps) == 0.0
    assert linalg.damping_factor(10 * eps) == 0.0
    s = np.linspace(0, eps, 50)
    mu = np.array([linalg.damping_factor(x) for x in s])
    assert np.all(np.diff(mu) <= 0)


def test_stacks_get_what_each_matrix_gets_alone():
    """projection, reduced_rates (exact and damped), min_pivot, the scenarios' pivots and the
    reduced singular values on a stack (B, m, n) equal the one-matrix calls row by row (one
    implementation serves the scalar API, the batched API and the whole-path planner)."""
    from fault_tolerance.numerics.linalg import min_pivot, projection, reduced_rates
    from fault_tolerance.resolution.indices import condition_numbers, reduced_singular_values
    from fault_tolerance.resolution.scenarios import scenarios

    rng = np.random.default_rng(7)
    Js = rng.normal(size=(25, 3, 6))
    Js[0, 2] = Js[0, 1]  # singular: damped
    Js[1, :, 4] = 0.0  # a zero column: locking joint 4 is free, N[4, 4] = 1
    xds = rng.normal(size=(25, 3))
    P = projection(Js)
    a = np.einsum("bij,bj->bi", P.Jpinv, xds)
    assert P.sigma_min.shape == (25,) and P.damped[0] and not P.damped[2]
    sc = scenarios([(0, 3), 2, (1, 4, 5)], 6, r=3)
    for b in range(len(Js)):
        one = projection(Js[b])
        np.testing.assert_allclose(P.Jpinv[b], one.Jpinv, rtol=0, atol=1e-14)
        np.testing.assert_allclose(P.N[b], one.N, rtol=0, atol=1e-14)
        assert P.sigma_min[b] == pytest.approx(one.sigma_min, abs=1e-15)
        np.testing.assert_allclose(sc.pivots(P.N)[b], sc.pivots(one.N), rtol=0, atol=1e-14)
        np.testing.assert_allclose(
            condition_numbers(reduced_singular_values(Js, sc))[b],
            condition_numbers(reduced_singular_values(Js[b], sc)),
            rtol=1e-13,
        )
        for S in sc.sets:
            assert min_pivot(P.N, S)[b] == pytest.approx(min_pivot(one.N, S), abs=1e-14)
            for damp in (False, True):
                np.testing.assert_allclose(
                    reduced_rates(a, P.N, S, damp)[b],
                    reduced_rates(a[b], one.N, S, damp),
                    rtol=1e-12,
                    atol=1e-12,
                )


@pytest.mark.parametrize("response", ["least_norm", "continuation"])
@pytest.mark.parametrize("lockable", [[0, 2, 4], [(0, 1), 3, (2, 5)]])
def test_jvja_rates_on_a_stack_are_jvja_row_by_row(response, lockable):
    """resolution.jvja.jvja_rates on a stack (the batched API's and the whole-path planner's
    JVJA) equals ft.resolve's jvja per row, exact and damped pivots (1e-10)."""
    from fault_tolerance.numerics.linalg import damped_pivots, projection
    from fault_tolerance.resolution.jvja import jvja, jvja_rates
    from fault_tolerance.resolution.scenarios import scenarios

    rng = np.random.default_rng(5)
    Js, xds = rng.normal(size=(12, 3, 6)), rng.normal(size=(12, 3))
    sc = scenarios(lockable, 6, r=3)
    P = projection(Js)
    a = np.einsum("bij,bj->bi", P.Jpinv, xds)
    for damp in (False, True):
        piv = damped_pivots(sc.pivots(P.N)) if damp else sc.pivots(P.N)
        got = jvja_rates(a, P.N, sc, piv, response, damp)
        for b in range(len(Js)):
            ref = jvja(Js[b], xds[b], lockable, response=response, tolerate=damp)
            np.testing.assert_allclose(got[b], ref, rtol=1e-10, atol=1e-10)
