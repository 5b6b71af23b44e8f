"""planner: LNVA, JVJA (eq. 5, G2, G3) and MDA, against the plain per-scenario implementation."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.linalg import reduced_rates_explicit
from fault_tolerance.resolution import jvja as planner
from fault_tolerance.resolution.mda import MDA_GAIN

ATOL = 1e-10
RTOL = 1e-9

RESOLVER_SPECS = {
    "lnva": ("lnva", {}),
    "jvja": ("jvja", {}),
    "jvja_continuation": ("jvja", {"response": "continuation"}),
    "jvja_weighted": ("jvja", {"weighted": True}),
    "jvja_weighted_continuation": ("jvja", {"weighted": True, "response": "continuation"}),
    "mda": ("mda", {"mda": True}),
    "mda_gain": ("mda", {"mda": True, "gain": 0.5}),
}


def _options(case, q, spec, rng, sets):
    """Keyword options of resolve() for one of RESOLVER_SPECS."""
    opts = dict(spec)
    if opts.pop("weighted", False):
        opts["weights"] = rng.uniform(0.1, 2.0, len(sets))
    if opts.pop("mda", False):
        opts.update(arm=case.arm, q=q)
    return opts


def _explicit_jvja(J, xd, sets, w):
    """Reference for eq. (3)-(4), independent of (5): argmin Σ_S w_S ‖ˢq̇' − q̇‖² s.t. J q̇ = ẋ.

    ˢq̇' = E_S J_S⁺ ẋ from numpy's pinv per scenario; the equality-constrained least squares is
    solved through its KKT system [[2 Σw I, Jᵀ], [J, 0]] [q̇; ν] = [2 Σ w_S ˢq̇'; ẋ].
    """
    m, n = J.shape
    post = []
    for S in sets:
        keep = [j for j in range(n) if j not in S]
        p = np.zeros(n)
        p[keep] = np.linalg.pinv(J[:, keep]) @ xd
        post.append(p)
    K = np.block([[2 * w.sum() * np.eye(n), J.T], [J, np.zeros((m, m))]])
    rhs = np.concatenate([2 * (w @ np.array(post)), xd])
    return np.linalg.solve(K, rhs)[:n]


def _continuation_weight(N, sets, w):
    """W = Σ_S w_S E_S N[S,S]⁻¹ E_Sᵀ: the continuation jump of feasible rates is q̇ᵀ W q̇."""
    W = np.zeros_like(N)
    for S, wS in zip(sets, w, strict=True):
        W[np.ix_(S, S)] += wS * np.linalg.inv(N[np.ix_(S, S)])
    return W


# -- J q̇ = ẋ ------------------------------------------------------------------------------


@pytest.mark.parametrize("spec", list(RESOLVER_SPECS), ids=list(RESOLVER_SPECS))
def test_every_resolver_tracks_the_task(robot, rng, draw_q, draw_xdot, spec):
    """J q̇ = ẋ for every resolver, response and weighting (multi-joint scenarios when r > 1)."""
    name, base = RESOLVER_SPECS[spec]
    sets = robot.sets
    for _ in range(3):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        qd = ft.resolve(name, J, xd, lockable=sets, **_options(robot, q, base, rng, sets))
        assert qd.shape == (robot.n,)
        # rounding of J q̇ grows with ‖q̇‖ (MDA's N∇K can be large near low dexterity)
        np.testing.assert_allclose(J @ qd, xd, atol=ATOL * max(1.0, np.linalg.norm(qd)))


@pytest.mark.parametrize("spec", list(RESOLVER_SPECS), ids=list(RESOLVER_SPECS))
def test_panda_position_two_joint_scenarios_track_the_task(panda_position, rng, draw_q, spec):
    """Panda position task (r = 4), scenarios [(0, 1), (2, 3)]: J q̇ = ẋ for every resolver."""
    name, base = RESOLVER_SPECS[spec]
    sets = [(0, 1), (2, 3)]
    q = draw_q(panda_position, rng, lockable=sets)
    J = panda_position.arm.jacobian(q)
    xd = rng.standard_normal(3)
    qd = ft.resolve(name, J, xd, lockable=sets, **_options(panda_position, q, base, rng, sets))
    np.testing.assert_allclose(J @ qd, xd, atol=ATOL * max(1.0, np.linalg.norm(qd)))


# -- eq. (5): closed form against the explicit implementation -------------------------------


@pytest.mark.parametrize("case", ["singletons", "weighted", "multi_joint", "multi_weighted"])
def test_jvja_equals_explicit_per_scenario_pseudo_inverses(robot, rng, draw_q, draw_xdot, case):
    """Eq. (5): JVJA's closed form (G2) equals J⁺ẋ + N·mean_w(E_S J_S⁺ ẋ) and the KKT minimiser."""
    if case.startswith("multi"):
        sets = robot.sets if robot.r > 1 else [(i,) for i in robot.lockable]
    else:
        sets = [(i,) for i in robot.lockable]
    for _ in range(3):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        w = rng.uniform(0.1, 3.0, len(sets)) if "weighted" in case else None
        fast = planner.jvja(J, xd, sets, weights=w)
        slow = planner.jvja_explicit(J, xd, sets, weights=w)
        ref = _explicit_jvja(J, xd, sets, np.ones(len(sets)) if w is None else w)
        np.testing.assert_allclose(fast, slow, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(fast, ref, rtol=1e-8, atol=ATOL)


def test_jvja_equals_explicit_on_panda_with_two_joint_scenarios(panda_position, rng, draw_q):
    """Eq. (5) on the Panda position task with [(0, 1), (2, 3)], unweighted and weighted."""
    sets = [(0, 1), (2, 3)]
    for w in (None, np.array([0.3, 1.7])):
        q = draw_q(panda_position, rng, lockable=sets)
        J = panda_position.arm.jacobian(q)
        xd = rng.standard_normal(3)
        np.testing.assert_allclose(
            planner.jvja(J, xd, sets, weights=w),
            _explicit_jvja(J, xd, sets, np.ones(2) if w is None else w),
            rtol=1e-8,
            atol=ATOL,
        )


def test_g2_closed_form(robot, rng, draw_q, draw_xdot):
    """(G2): q̇ = a − N c / f with cᵢ = aᵢ / Nᵢᵢ for i ∈ F and 0 elsewhere."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    proj = ft.projection(J)
    a, N = proj.Jpinv @ xd, proj.N
    F = list(robot.lockable)
    c = np.zeros(robot.n)
    c[F] = a[F] / np.diag(N)[F]
    np.testing.assert_allclose(ft.jvja(J, xd, F), a - N @ c / len(F), rtol=RTOL, atol=ATOL)


def test_g2_for_r_equal_1_uses_the_unit_null_vector(r1_robot, rng, draw_q, draw_xdot):
    """(G2), r = 1: q̇ = a − n · mean_{i∈F}(aᵢ / nᵢ) with n the unit null vector of J."""
    case = r1_robot
    q = draw_q(case, rng)
    J = case.arm.jacobian(q)
    xd = draw_xdot(rng, case.m)
    n_vec = np.linalg.svd(J)[2][-1]
    np.testing.assert_allclose(J @ n_vec, 0.0, atol=ATOL)
    a = np.linalg.pinv(J) @ xd
    F = list(case.lockable)
    expected = a - n_vec * np.mean(a[F] / n_vec[F])
    np.testing.assert_allclose(ft.jvja(J, xd, F), expected, rtol=RTOL, atol=ATOL)


# -- eq. (8) --------------------------------------------------------------------------------


@pytest.mark.parametrize("response", ["least_norm", "continuation"])
def test_single_lockable_joint_is_held_still_and_jump_is_zero(
    robot, rng, draw_q, draw_xdot, response
):
    """Eq. (8): with only joint k lockable, JVJA gives q̇ₖ = 0 exactly and the jump λ is 0."""
    for k in robot.lockable:
        q = draw_q(robot, rng, lockable=[k])
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        qd = ft.jvja(J, xd, [k], response=response)
        np.testing.assert_allclose(qd[k], 0.0, atol=1e-12)
        np.testing.assert_allclose(ft.jvj(J, xd, qd, [k], response=response), 0.0, atol=1e-12)
        np.testing.assert_allclose(J @ qd, xd, atol=ATOL)
        if response == "least_norm":
            # q̇ = ᵏq̇': the rates of the reduced robot
            np.testing.assert_allclose(qd, reduced_rates_explicit(J, xd, [k]), rtol=RTOL, atol=ATOL)


# -- JVJA minimises the jump ----------------------------------------------------------------


def test_jvja_jump_never_above_lnva_mda_or_any_feasible_rates(robot, rng, draw_q, draw_xdot):
    """λ(JVJA) <= λ(LNVA), λ(JVJA) <= λ(MDA) and <= λ of any rates with J q̇ = ẋ."""
    sets = robot.sets
    for _ in range(5):
        q = draw_q(robot, rng, lockable=sets)
        J = robot.arm.jacobian(q)
        xd = draw_xdot(rng, robot.m)
        best = ft.jvj(J, xd, ft.resolve("jvja", J, xd, sets), sets)
        tol = ATOL * max(1.0, best)
        N = ft.nullspace_projector(J)
        others = [ft.resolve("lnva", J, xd, sets)]
        others += [ft.resolve("mda", J, xd, sets, arm=robot.arm, q=q)]
        others += [ft.resolve("mda", J, xd, sets, arm=robot.arm, q=q, gain=g) for g in (0.1, 1.0)]
        others += [ft.lnva(J, xd) + N @ rng.standard_normal(robot.n) for _ in range(5)]
        for qd in others:
            assert best <= ft.jvj(J, xd, qd, sets) + tol


# -- (G3): least-norm response vs continuation response -------------------------------------
# MATH.md (G3) claims: "Both responses coincide when r = 1; for r > 1 the continuation jump is
# never larger." Precisely, for any rates q̇ with J q̇ = ẋ and any tolerable scenario S:
#   (i)   r = 1: ˢq̇'' = ˢq̇' (so the jumps, and the two minimum-jump rates, coincide);
#   (ii)  r > 1: ‖ˢq̇'' − q̇‖ <= ‖ˢq̇' − q̇‖ (ˢq̇'' is the nearest reduced solution to q̇),
#         hence λ_cont(q̇) <= λ_LN(q̇) for every feasible q̇, and so
#         min λ_cont = λ_cont(q̇_cont-opt) <= λ_cont(q̇_JVJA) <= λ_LN(q̇_JVJA) = min λ_LN;
#   (iii) q̇ = a + N z, z = −(N W N)⁺ N W a minimises λ_cont over the feasible rates.


def test_g3_responses_coincide_when_r_is_1(r1_robot, rng, draw_q, draw_xdot):
    """(G3) r = 1: both responses give the same rates, and the same jump for any feasible q̇."""
    case = r1_robot
    for weights in (None, rng.uniform(0.1, 2.0, len(case.lockable))):
        q = draw_q(case, rng)
        J = case.arm.jacobian(q)
        xd = draw_xdot(rng, case.m)
        F = list(case.lockable)
        ln = ft.jvja(J, xd, F, weights=weights)
        co = ft.jvja(J, xd, F, weights=weights, response="continuation")
        np.testing.assert_allclose(co, ln, rtol=1e-8, atol=ATOL)
        qd = ft.lnva(J, xd) + ft.nullspace_projector(J) @ rng.standard_normal(case.n)
        np.testing.assert_allclose(
            ft.jvj(J, xd, qd, F, weights=weights, response="continuation"),
            ft.jvj(J, xd, qd, F, weights=weights),
            rtol=1e-8,
            atol=ATOL,
        )


@pytest.mark.parametrize("multi", [False, True])
def test_g3_continuation_jump_never_larger_when_r_above_1(redundant_robot, rng, draw_q, multi):
    """(G3) r > 1: λ_cont(q̇) <= λ_LN(q̇) for feasible q̇, and min λ_cont <= λ_LN(JVJA) = min λ_LN."""
    case = redundant_robot
    sets = case.sets if multi else [(i,) for i in case.lockable]
    strict = 0.0
    for _ in range(5):
        q = draw_q(case, rng, lockable=sets)
        J = case.arm.jacobian(q)
        xd = rng.standard_normal(case.m)
        w = rng.uniform(0.1, 2.0, len(sets))
        ln = ft.jvja(J, xd, sets, weights=w)
        co = ft.jvja(J, xd, sets, weights=w, response="continuation")
        lam_ln = ft.jvj(J, xd, ln, sets, weights=w)
        lam_co = ft.jvj(J, xd, co, sets, weights=w, response="continuation")
        tol = ATOL * max(1.0, lam_ln)
        assert lam_co <= ft.jvj(J, xd, ln, sets, weights=w, response="continuation") + tol
        assert lam_co <= lam_ln + tol
        strict = max(strict, (lam_ln - lam_co) / max(lam_ln, 1e-300))
        N = ft.nullspace_projector(J)
        for _ in range(5):  # per feasible rates: continuation jump never larger
            qd = ft.lnva(J, xd) + N @ rng.standard_normal(case.n)
            assert ft.jvj(J, xd, qd, sets, weights=w, response="continuation") <= (
                ft.jvj(J, xd, qd, sets, weights=w) + ATOL * max(1.0, lam_ln)
            )
    assert strict > 1e-3  # for r > 1 the two models genuinely differ


def test_g3_continuation_rates_minimise_the_continuation_jump(redundant_robot, rng, draw_q):
    """(G3) a + N z with z = −(NWN)⁺NWa minimises λ_cont = q̇ᵀWq̇ over {J q̇ = ẋ} (KKT reference)."""
    case = redundant_robot
    for sets in ([(i,) for i in case.lockable], case.sets, case.multi[:2]):
        q = draw_q(case, rng, lockable=sets)
        J = case.arm.jacobian(q)
        xd = rng.standard_normal(case.m)
        w = rng.uniform(0.1, 2.0, len(sets))
        N = ft.nullspace_projector(J)
        W = _continuation_weight(N, sets, w)
        co = ft.jvja(J, xd, sets, weights=w, response="continuation")
        lam = ft.jvj(J, xd, co, sets, weights=w, response="continuation")
        np.testing.assert_allclose(lam, co @ W @ co, rtol=1e-8, atol=ATOL)
        m, n = J.shape
        K = np.block([[2 * W, J.T], [J, np.zeros((m, m))]])
        sol = np.linalg.lstsq(K, np.concatenate([np.zeros(n), xd]), rcond=None)[0][:n]
        np.testing.assert_allclose(J @ sol, xd, atol=1e-8)
        np.testing.assert_allclose(lam, sol @ W @ sol, rtol=1e-7, atol=ATOL)
        for _ in range(5):
            other = co + N @ (1e-3 * rng.standard_normal(n))
            assert lam <= other @ W @ other + ATOL * max(1.0, lam)


# -- MDA ------------------------------------------------------------------------------------


def test_mda_with_zero_gain_is_lnva(robot, rng, draw_q, draw_xdot):
    """MDA with α = 0 is LNVA."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    np.testing.assert_allclose(
        ft.mda(J, xd, list(robot.lockable), arm=robot.arm, q=q, gain=0.0), ft.lnva(J, xd), atol=0
    )


def test_mda_is_lnva_minus_projected_gradient(robot, rng, draw_q, draw_xdot):
    """MDA: q̇ = J⁺ẋ − α N ∇K, and passing dJ directly equals passing arm and q."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    xd = draw_xdot(rng, robot.m)
    F = list(robot.lockable)
    dJ = robot.arm.jacobian_derivatives(q)
    grad = ft.rcn_gradient(J, dJ, F)
    alpha = 0.05
    expected = ft.lnva(J, xd) - alpha * ft.nullspace_projector(J) @ grad
    np.testing.assert_allclose(
        ft.mda(J, xd, F, arm=robot.arm, q=q, gain=alpha), expected, atol=ATOL
    )
    np.testing.assert_allclose(ft.mda(J, xd, F, dJ=dJ, gain=alpha), expected, atol=ATOL)
    default = ft.lnva(J, xd) - MDA_GAIN * ft.nullspace_projector(J) @ grad
    np.testing.assert_allclose(ft.mda(J, xd, F, dJ=dJ), default, atol=ATOL)


def test_mda_self_motion_descends_k(robot, rng, draw_q):
    """With ẋ = 0, MDA moves along −N∇K: dK/dt = ∇Kᵀq̇ = −α‖N∇K‖² <= 0."""
    q = draw_q(robot, rng)
    J = robot.arm.jacobian(q)
    F = list(robot.lockable)
    grad = ft.rcn_gradient(J, robot.arm.jacobian_derivatives(q), F)
    qd = ft.mda(J, np.zeros(robot.m), F, arm=robot.arm, q=q, gain=0.1)
    Ng = ft.nullspace_projector(J) @ grad
    np.testing.assert_allclose(grad @ qd, -0.1 * Ng @ Ng, rtol=1e-9, atol=ATOL)
    assert grad @ qd <= 0.0


@pytest.mark.parametrize(
    "kwargs, match", [({}, "arm=..."), ({"gain": -1.0}, "gain"), ({"gain": np.nan}, "gain")]
)
def test_mda_input_errors(planar_3r, kwargs, match):
    """MDA without a configuration, or with a negative/non-finite gain, raises InvalidInput."""
    q = np.array([0.3, 1.2, 1.0])
    J = planar_3r.arm.jacobian(q)
    if "gain" in kwargs:
        kwargs = dict(kwargs, arm=planar_3r.arm, q=q)
    with pytest.raises(ft.InvalidInput, match=match):
        ft.resolve("mda", J, np.array([0.1, 0.0]), **kwargs)


# -- resolve() ------------------------------------------------------------------------------


def test_registry_names():
    """The built-ins lnva, jvja and mda are registered first, then the inertia-weighted JVJA."""
    assert ft.registry.names()[:4] == ("lnva", "jvja", "mda", "jvja_inertia")


def test_resolve_unknown_name_lists_the_resolvers(planar_3r):
    """An unknown resolver name raises InvalidInput listing the known ones."""
    J = planar_3r.arm.jacobian(np.array([0.3, 1.2, 1.0]))
    with pytest.raises(ft.InvalidInput, match=r"\['jvja', 'jvja_inertia', 'lnva', 'mda'\]"):
        ft.resolve("fastest", J, np.zeros(2))


@pytest.mark.parametrize(
    "J, xd",
    [
        (np.ones((2, 3)), np.zeros(3)),
        (np.ones(3), np.zeros(1)),
        (np.ones((2, 3)), np.zeros((2, 1))),
        (np.array([[1.0, np.nan, 0.0], [0.0, 1.0, 0.0]]), np.zeros(2)),
        (np.eye(2, 3), np.array([np.inf, 0.0])),
    ],
    ids=["xdot-length", "J-1d", "xdot-2d", "J-nan", "xdot-inf"],
)
def test_resolve_rejects_bad_shapes_and_non_finite(J, xd):
    """resolve() refuses J that is not (m, n), ẋ that is not (m,), and non-finite entries."""
    with pytest.raises(ft.InvalidInput):
        ft.resolve("lnva", J, xd)


def test_lockable_by_joint_names(planar_3r, rng, draw_q):
    """Joint names with joint_names= select the same scenarios as column indices."""
    arm = planar_3r.arm
    q = draw_q(planar_3r, rng)
    J = arm.jacobian(q)
    xd = np.array([0.1, -0.2])
    np.testing.assert_allclose(
        ft.resolve("jvja", J, xd, lockable=["joint2", "joint3"], joint_names=arm.joint_names),
        ft.resolve("jvja", J, xd, lockable=[1, 2]),
        atol=0,
    )


def test_lnva_ignores_lockable(robot, rng, draw_q, draw_xdot):
    """LNVA is J⁺ẋ whatever the lockable set."""
    J = robot.arm.jacobian(draw_q(robot, rng))
    xd = draw_xdot(rng, robot.m)
    np.testing.assert_allclose(
        ft.resolve("lnva", J, xd, lockable=[0]), np.linalg.pinv(J) @ xd, atol=ATOL
    )


def test_jvja_rejects_unknown_response(planar_3r):
    """An unknown response model is refused, naming the allowed ones."""
    J = planar_3r.arm.jacobian(np.array([0.3, 1.2, 1.0]))
    with pytest.raises(Exception, match="continuation"):
        ft.jvja(J, np.array([0.1, 0.0]), response="sideways")
