"""Bounded resolvers: equal to a generic QP solver (quadprog) on the same problem."""

import numpy as np
import pytest
import quadprog
from scipy.optimize import linprog

import fault_tolerance as ft
from fault_tolerance.errors import InfeasibleBounds, IntolerableUnderLimits, InvalidInput
from fault_tolerance.model import joint_limits
from fault_tolerance.resolution import bounded, limits

REL = 1e-6


def qp_ref(H, c, J, xdot, lo, hi, keep=None):
    """quadprog: min ½(q̇−c)ᵀH(q̇−c) s.t. J q̇ = ẋ, lo ≤ q̇ ≤ hi (over the columns ``keep``)."""
    n = J.shape[1]
    keep = np.arange(n) if keep is None else np.asarray(keep)
    Jk, Hk, ck = J[:, keep], H[np.ix_(keep, keep)], c[keep]
    k = len(keep)
    C = np.hstack([Jk.T, np.eye(k), -np.eye(k)])
    b = np.concatenate([xdot, lo[keep], -hi[keep]])
    x = quadprog.solve_qp(Hk, Hk @ ck, C, b, J.shape[0])[0]
    out = np.zeros(n)
    out[keep] = x
    return out


def feasible(J, xdot, lo, hi, keep=None):
    n = J.shape[1]
    keep = np.arange(n) if keep is None else np.asarray(keep)
    res = linprog(
        np.zeros(len(keep)),
        A_eq=J[:, keep],
        b_eq=xdot,
        bounds=list(zip(lo[keep], hi[keep], strict=True)),
        method="highs",
        options={"primal_feasibility_tolerance": 1e-10},
    )
    return res.status == 0


def random_problem(rng, m, n, tight):
    J = rng.normal(size=(m, n))
    xdot = rng.normal(size=m)
    a = np.linalg.pinv(J) @ xdot
    width = np.abs(a).max() * (tight if tight else 10.0)
    lo = -rng.uniform(0.2, 1.0, n) * width
    hi = rng.uniform(0.2, 1.0, n) * width
    return J, xdot, lo, hi


def reduced_refs(J, xdot, sets, lo, hi):
    n = J.shape[1]
    return np.array(
        [
            qp_ref(np.eye(n), np.zeros(n), J, xdot, lo, hi, [j for j in range(n) if j not in S])
            for S in sets
        ]
    )


def check_scaled(J, xdot, out, lo, hi):
    """s < 1: J q̇ = s ẋ inside the box, and s ẋ (1 + 1e-5) unreachable."""
    assert np.all(out.qd >= lo - 1e-12) and np.all(out.qd <= hi + 1e-12)
    assert np.allclose(J @ out.qd, out.scale * xdot, atol=1e-9)
    assert not feasible(J, out.scale * (1 + 1e-5) * xdot, lo, hi)


CASES = [(2, 3), (2, 4), (3, 7), (1, 4), (3, 5)]


@pytest.mark.parametrize("tight", [None, 0.9, 0.5, 0.2])
@pytest.mark.parametrize("m,n", CASES)
def test_lnva_equals_qp(m, n, tight):
    rng = np.random.default_rng(100 * m + n + int(10 * (tight or 0)))
    for _ in range(15):
        J, xd, lo, hi = random_problem(rng, m, n, tight)
        out = ft.resolve_bounded("lnva", J, xd, bounds=(lo, hi))
        if out.scale < 1:
            assert not feasible(J, xd, lo, hi)
            check_scaled(J, xd, out, lo, hi)
            continue
        ref = qp_ref(np.eye(n), np.zeros(n), J, xd, lo, hi)
        assert abs(out.qd @ out.qd - ref @ ref) <= REL * (ref @ ref)
        assert np.allclose(out.qd, ref, atol=1e-7)
        assert bool(out.active.any()) == (not np.allclose(ref, np.linalg.pinv(J) @ xd))


@pytest.mark.parametrize("weights", [None, "random"])
@pytest.mark.parametrize("tight", [None, 0.9, 0.5])
@pytest.mark.parametrize("m,n", CASES)
def test_jvja_least_norm_equals_qp(m, n, tight, weights):
    rng = np.random.default_rng(7 * m + n + int(10 * (tight or 0)))
    for _ in range(10):
        J, xd, lo, hi = random_problem(rng, m, n, tight)
        sets = [(j,) for j in range(n)]
        if n - m >= 2:
            sets += [(0, 1)]  # a multi-joint scenario
        w = None if weights is None else rng.uniform(0.5, 2.0, len(sets))
        if not all(feasible(J, xd, lo, hi, [j for j in range(n) if j not in S]) for S in sets):
            out = ft.resolve_bounded("jvja", J, xd, sets, bounds=(lo, hi), weights=w)
            assert np.any(out.reduced_scale < 1 - 1e-9)
            continue
        out = ft.resolve_bounded("jvja", J, xd, sets, bounds=(lo, hi), weights=w)
        assert np.all(out.reduced_scale == 1.0)
        ww = np.ones(len(sets)) if w is None else w
        post = reduced_refs(J, xd, sets, lo, hi)
        c = ww @ post / ww.sum()
        if not feasible(J, xd, lo, hi):
            check_scaled(J, xd, out, lo, hi)
            continue
        ref = qp_ref(np.eye(n), c, J, xd, lo, hi)
        lam = lambda qd, ww=ww, post=post: float(ww @ ((post - qd) ** 2).sum(axis=1))  # noqa: E731
        assert abs(lam(out.qd) - lam(ref)) <= REL * lam(ref)
        assert np.allclose(out.qd, ref, atol=1e-7)
        # inside the box and no reduced bound: the unbounded JVJA unchanged
        if (
            not out.active.any()
            and np.all(post >= lo)
            and np.allclose(post, reduced_refs(J, xd, sets, lo - 1e9, hi + 1e9))
        ):
            assert np.allclose(out.qd, ft.jvja(J, xd, sets, weights=w), atol=1e-10)


@pytest.mark.parametrize("tight", [None, 0.9, 0.5])
@pytest.mark.parametrize("m,n", [(2, 4), (3, 7), (1, 4), (3, 6)])
def test_jvja_continuation_equals_qp(m, n, tight):
    rng = np.random.default_rng(3 * m + n + int(10 * (tight or 0)))
    for _ in range(10):
        J, xd, lo, hi = random_problem(rng, m, n, tight)
        sets = [(j,) for j in range(n)] + [(0, 1)]
        out = ft.resolve_bounded("jvja", J, xd, sets, bounds=(lo, hi), response="continuation")
        Jp = np.linalg.pinv(J)
        N = np.eye(n) - Jp @ J
        W = np.zeros((n, n))
        for S in sets:
            W[np.ix_(S, S)] += np.linalg.inv(N[np.ix_(S, S)])
        H = W + bounded.CONTINUATION_EPS * np.trace(W) / n * np.eye(n)
        if not feasible(J, xd, lo, hi):
            check_scaled(J, xd, out, lo, hi)
            continue
        ref = qp_ref(H, np.zeros(n), J, xd, lo, hi)
        Z = lambda qd, W=W: float(qd @ W @ qd)  # noqa: E731  the (G3) jump
        assert abs(Z(out.qd) - Z(ref)) <= REL * Z(ref)
        assert np.allclose(out.qd, ref, atol=1e-6)
        if not out.active.any():
            unb = ft.jvja(J, xd, sets, response="continuation")
            assert abs(Z(unb) - Z(out.qd)) <= REL * Z(unb)


@pytest.mark.parametrize("tight", [None, 0.9, 0.4])
def test_mda_equals_qp(tight):
    arm = ft.load_arm("spatial_4r")
    rng = np.random.default_rng(5)
    for _ in range(10):
        q = arm.random_q(rng)
        J = arm.jacobian(q)
        xd = rng.normal(size=arm.m) * 0.1
        unb = ft.resolve("mda", J, xd, [0, 1, 2], arm=arm, q=q, gain=0.05)
        width = np.abs(unb).max() * (tight or 10.0)
        lo, hi = -rng.uniform(0.2, 1, 4) * width, rng.uniform(0.2, 1, 4) * width
        out = ft.resolve_bounded("mda", J, xd, [0, 1, 2], arm=arm, q=q, gain=0.05, bounds=(lo, hi))
        if not feasible(J, xd, lo, hi):
            check_scaled(J, xd, out, lo, hi)
            continue
        c = unb - np.linalg.pinv(J) @ xd  # −α N∇K (capped): the target MDA projects
        ref = qp_ref(np.eye(4), c, J, xd, lo, hi)
        f = lambda qd, c=c: float((qd - c) @ (qd - c))  # noqa: E731
        assert abs(f(out.qd) - f(ref)) <= REL * f(ref)
        assert np.allclose(out.qd, ref, atol=1e-7)


def test_bounds_through_resolve_and_unknown_options_raise():
    J = np.array([[1.0, 1.0, 1.0]])
    xd = np.array([0.3])
    qd = ft.resolve("lnva", J, xd, bounds=([-1, -1, -1], [1, 1, 0.05]))
    assert np.allclose(qd, [0.125, 0.125, 0.05])
    with pytest.raises(InvalidInput, match="unknown option"):
        ft.resolve("jvja", J, xd, bound=([-1] * 3, [1] * 3))
    with pytest.raises(TypeError):
        ft.lnva(J, xd, bounds=None)
    with pytest.raises(InvalidInput, match="qd_lo > qd_hi"):
        ft.resolve("lnva", J, xd, bounds=([0, 0, 1], [1, 1, 0]))
    with pytest.raises(InvalidInput, match="pair"):
        ft.resolve("lnva", J, xd, bounds=[1.0])


def test_no_rate_reaches_even_zero():
    J = np.array([[1.0, 1.0, 1.0]])
    with pytest.raises(InfeasibleBounds):
        ft.resolve_bounded("lnva", J, np.array([0.2]), bounds=([0.1] * 3, [0.2] * 3))


def test_scaling_reported():
    J = np.array([[1.0, 1.0, 1.0]])
    out = ft.resolve_bounded("lnva", J, np.array([0.3]), bounds=([-0.1] * 3, [0.1, 0.1, 0.05]))
    assert out.scale == pytest.approx(0.25 / 0.3)
    assert out.active.all()


def test_rate_box():
    lo, hi = ft.rate_box([0.0, 0.99, 0.0], [-1, -1, -np.inf], [1, 1, 1e300], [2.0, 2.0, 1.0], 0.05)
    assert np.allclose(hi, [2.0, 0.2, 1.0]) and np.allclose(lo, [-2.0, -2.0, -1.0])
    with pytest.raises(InvalidInput, match="horizon"):
        ft.rate_box([0.0], [-1], [1], [1], 0.0)


def test_reduced_robot_intolerable_under_limits():
    # locking joint 0 leaves joints 1, 2 which reach at most 0.1 + 0.05 < 0.3
    J = np.array([[1.0, 1.0, 1.0]])
    bounds = ([-1, -0.1, -0.05], [1, 0.1, 0.05])
    s = limits.tolerable_under_limits(J, np.array([0.3]), [0, 1], bounds=bounds)
    assert s[0] == pytest.approx(0.5) and s[1] == 1.0
    lam = ft.jvj(J, [0.3], [0.1, 0.1, 0.1], [1], bounds=bounds)
    # reduced robot with joint 1 locked: bounded least norm [0.25, 0, 0.05]
    assert lam == pytest.approx(0.15**2 + 0.1**2 + 0.05**2)
    with pytest.raises(IntolerableUnderLimits, match="joint index 0"):
        ft.jvj(J, [0.3], [0.1, 0.1, 0.1], [0, 1], bounds=bounds)
    # without limits the same scenario is tolerable
    assert ft.jvj(J, [0.3], [0.1, 0.1, 0.1], [0, 1]) >= 0


def test_guaranteed_speed_exact_and_sampled():
    rng = np.random.default_rng(2)
    for m, n in [(1, 3), (2, 3), (3, 5), (3, 7)]:
        J = rng.normal(size=(m, n))
        lo, hi = -rng.uniform(0.1, 1, n), rng.uniform(0.1, 1, n)
        rho = limits.guaranteed_speed(J, lo, hi)
        assert rho > 0
        # every direction is reachable at speed rho, and some direction not much beyond it
        dirs = rng.normal(size=(40, m))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        for d in dirs:
            assert feasible(J, rho * (1 - 1e-6) * d, lo, hi)
        y = rng.normal(size=(20000, m))
        y /= np.linalg.norm(y, axis=1, keepdims=True)
        C = y @ J
        assert rho <= np.maximum(C * lo, C * hi).sum(axis=1).min() + 1e-12
    # a joint at its lower limit with lo = 0 leaves one direction unreachable for a 1-joint robot
    assert limits.guaranteed_speed(np.array([[1.0]]), [0.0], [1.0]) == 0.0


def test_arm_rate_bounds_and_inspect():
    arm = ft.load_arm("panda")
    q = arm.q_reference.copy()
    q[3] = arm.upper[3] - 0.01  # 1 cm rad from the upper limit
    lo, hi = arm.rate_bounds(q)
    assert hi[3] == pytest.approx(0.01 / joint_limits.RATE_HORIZON)
    assert np.allclose(lo, -arm.velocity_limit) and np.all(hi <= arm.velocity_limit)
    assert np.all(joint_limits.outside_limits(arm, q) == False)  # noqa: E712
    from fault_tolerance.analysis.inspection import inspect_text

    text = inspect_text("panda")
    assert "under joint limits there" in text and "intolerable under limits only" in text


def test_velocity_defaults_where_urdf_has_none():
    arm = ft.load_arm("planar_3r")
    arm.model.velocityLimit = np.array([0.0, np.inf, 2.0])
    assert np.allclose(joint_limits.velocity_limits(arm), [np.pi, np.pi, 2.0])


#: A configuration of the bench's chain_14 pool (inside the limits) whose reduced robot of joint 8
#: raised InfeasibleBounds; its task velocity.
CHAIN14_Q = np.array([
    -2.3923756975384443, -3.075698276536998, 1.8522491693721665, 2.674856937765739,
    -1.8800748833421963, 1.9498193872681737, -2.103904791012074, -2.7374498891695667,
    -1.1115195167287855, -1.1369592512408544, 1.7428178159548011, -3.085152356888032,
    -1.8613265982059963, -2.30215240953327])  # fmt: skip
CHAIN14_XD = np.array([
    -0.6063841328681505, -0.3732927189455615, 0.659764605007273, 0.139906488448801,
    -0.18644615194521597, 0.057667168148914136])  # fmt: skip


def max_scale(J, xdot, lo, hi, keep):
    """The largest s in [0, 1] with J_keep q̇ = s ẋ inside the box (linprog): (L3)'s reference."""
    k = len(keep)
    res = linprog(np.r_[np.zeros(k), -1.0], A_eq=np.hstack([J[:, keep], -xdot[:, None]]),
                  b_eq=np.zeros(len(xdot)), bounds=[*zip(lo[keep], hi[keep], strict=True), (0, 1)],
                  method="highs")  # fmt: skip
    return res.x[-1]


def test_chain_14_near_dependent_bounds_are_not_infeasible():
    """The bench's chain_14 pool: 0 is inside the box, yet the reduced robot of joint 8
    raised InfeasibleBounds ("not even zero"): seven nearly parallel bounds in its null space made
    the active-set step (normal equations, a tiny ``z`` when the active rows spanned R^r) huge and
    the Farkas certificate meaningless. Rates inside the box, J q̇ = s ẋ, s the largest."""
    from fault_tolerance.bench.chain import synthetic_chain

    q, xd = CHAIN14_Q, CHAIN14_XD
    arm = synthetic_chain(14)
    J, (lo, hi), n = arm.jacobian(q), arm.rate_bounds(q, 0.05), 14
    assert (lo <= 0).all() and (hi >= 0).all()  # s = 0 with zero rates is feasible
    sc = ft.scenarios("all", n, r=n - 6)
    out = ft.resolve_bounded("jvja", J, xd, sc, bounds=(lo, hi))
    post, scales = bounded.reduced_under_limits(J, xd, sc, lo, hi)
    solved = []
    for k, S in enumerate(sc.sets):  # every reduced robot: its largest s, quadprog's optimum there
        keep = [j for j in range(n) if j not in S]
        assert 0.0 <= scales[k] <= 1.0
        assert scales[k] == pytest.approx(max_scale(J, xd, lo, hi, keep), abs=1e-9)
        assert (post[k] >= lo - 1e-12).all() and (post[k] <= hi + 1e-12).all()
        assert post[k][S[0]] == 0
        assert np.abs(J @ post[k] - scales[k] * xd).max() < 1e-10
        try:  # at its largest s the set may be a point: quadprog may call it inconsistent
            ref = qp_ref(np.eye(n), np.zeros(n), J, scales[k] * xd, lo, hi, keep)
        except ValueError:
            continue
        solved.append(S[0])
        assert np.abs(post[k] - ref).max() < 1e-6
    assert 7 in solved  # the robot that raised
    s = out.scale
    assert 0.0 <= s <= 1.0 and s == pytest.approx(max_scale(J, xd, lo, hi, range(n)), abs=1e-9)
    assert (out.qd >= lo - 1e-12).all() and (out.qd <= hi + 1e-12).all()
    assert np.abs(J @ out.qd - s * xd).max() < 1e-10
    c = sc.weights @ post / sc.weights.sum()
    assert np.abs(out.qd - qp_ref(np.eye(n), c, J, s * xd, lo, hi)).max() < 1e-6
