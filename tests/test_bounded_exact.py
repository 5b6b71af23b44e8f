"""Bounded resolvers against an independent LP (HiGHS) and QP (quadprog), near reduced singularities."""

import numpy as np
import pytest
import quadprog
from scipy.optimize import linprog

from fault_tolerance.numerics.linalg import projection
from fault_tolerance.resolution.bounded import reduced_bounded, resolve_bounded
from fault_tolerance.resolution.limits import tolerable_under_limits

SCALE_ATOL = 1e-8
RATE_ATOL = 1e-6


def lp_scale(J, xd, lo, hi):
    """Largest s in [0, 1] with J v = s xd, lo <= v <= hi (HiGHS)."""
    m, n = J.shape
    res = linprog(
        np.r_[np.zeros(n), -1.0],
        A_eq=np.hstack([J, -xd[:, None]]),
        b_eq=np.zeros(m),
        bounds=[*zip(lo, hi, strict=True), (0.0, 1.0)],
        method="highs",
        options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
    )
    if res.status != 0:  # HiGHS undecided (status 4) on a nearly degenerate LP: not compared
        return None
    return float(res.x[-1])


def qp_nearest(J, b, lo, hi, c, H=None, with_shrink=False):
    """min ½(v−c)ᵀH(v−c) s.t. J v = b, lo <= v <= hi (quadprog, dependent rows removed)."""
    n = J.shape[1]
    U, sv, _ = np.linalg.svd(J, full_matrices=False)
    k = int(np.sum(sv > 1e-9 * max(sv[0], 1e-300)))
    A, bb = U[:, :k].T @ J, U[:, :k].T @ b
    H = np.eye(n) if H is None else H
    C = np.hstack([A.T, np.eye(n), -np.eye(n)])
    lo_s = np.where(np.isfinite(lo), lo, -1e9)
    hi_s = np.where(np.isfinite(hi), hi, 1e9)
    for shrink in (0.0, 1e-10, 1e-9, 1e-8):  # at the largest scale the set may touch a point
        try:
            b_s = np.r_[bb * (1 - shrink), lo_s, -hi_s]
            v = quadprog.solve_qp(H, H @ c, C, b_s, meq=k)[0]
            return (v, shrink) if with_shrink else v
        except ValueError:
            continue
    raise ValueError("quadprog found no point even at a scale 1e-8 below")


def forced(J, qd, lo, hi) -> bool:
    """The joints off their bounds have independent columns: the task fixes them (a vertex).

    Then feasible rates are the only ones with that active set; quadprog's own equality residual
    (~1e-11) moves them by that over the free columns' σ_min, more than any comparison tolerance.
    """
    free = (qd > lo + 1e-12) & (qd < hi - 1e-12)
    return bool(np.linalg.matrix_rank(J[:, free], tol=1e-12) == free.sum())


def face_sensitivity(J, xd, qd, lo, hi, ds=1e-12) -> float:
    """How far the rates on their face move when ``s`` moves by ``ds`` (its bisection accuracy)."""
    free = (qd > lo + 1e-12) & (qd < hi - 1e-12)
    if not free.any():
        return 0.0
    sv = np.linalg.svd(J[:, free], compute_uv=False)
    return float(min(ds * np.linalg.norm(xd) / max(sv[-1], 1e-300), 1.0))


def assert_matches_qp(J, xd, out, lo, hi, c):
    """``out.qd`` is quadprog's nearest rates to ``c`` at ``out.scale``.

    At the largest scale the feasible set can be a sliver quadprog calls empty; it then solves a
    scale just below, and the rates need only be feasible at ``out.scale`` and as near to ``c``.
    """
    np.testing.assert_allclose(J @ out.qd, out.scale * xd, atol=1e-10)
    assert np.all(out.qd >= lo - 1e-12) and np.all(out.qd <= hi + 1e-12)
    try:
        ref, shrink = qp_nearest(J, out.scale * xd, lo, hi, c, with_shrink=True)
    except ValueError:  # quadprog found the sliver empty even a little below: not compared
        return False
    if shrink == 0.0 and out.scale == 1.0:
        np.testing.assert_allclose(out.qd, ref, atol=RATE_ATOL)
        return True
    if shrink == 0.0:  # on the LP's face the rates move by (rounding of s) / σ of the free columns
        f_ours, f_ref = np.sum((out.qd - c) ** 2), np.sum((ref - c) ** 2)
        dv = face_sensitivity(J, xd, out.qd, lo, hi)
        slack = 2.0 * np.linalg.norm(out.qd - c) * dv + dv**2
        assert f_ours <= f_ref * (1 + 1e-6) + slack + 1e-12, (f_ours, f_ref, dv)
        return True
    np.testing.assert_allclose(J @ out.qd, out.scale * xd, atol=1e-12)
    assert np.all(out.qd >= lo - 1e-12) and np.all(out.qd <= hi + 1e-12)
    if forced(J, out.qd, lo, hi):
        return True
    assert np.sum((out.qd - c) ** 2) <= np.sum((ref - c) ** 2) * (1 + 1e-2) + 1e-9
    return True


def assert_continuation_optimal(J, xd, lockable, out, lo, hi):
    """The continuation rates minimise qdᵀ H qd at their scale as well as quadprog finds (H of (L2))."""
    from fault_tolerance.resolution.bounded import _continuation_metric, _scenarios

    sc = _scenarios(J, lockable, None, ())
    H = _continuation_metric(projection(J).N, sc, True)
    H = 0.5 * (H + H.T)
    try:
        ref, shrink = qp_nearest(
            J, out.scale * xd, lo, hi, np.zeros(J.shape[1]), H=H, with_shrink=True
        )
    except ValueError:  # quadprog refuses H (ε I at 1e-10) or the sliver: not compared
        return False
    if forced(J, out.qd, lo, hi):  # (feasible: checked by the caller)
        return True
    f_ours, f_ref = out.qd @ H @ out.qd, ref @ H @ ref
    # a scaled task is solved on the LP's face, where the free rates move by (rounding of s)/σ of
    # the free columns (1e-12/1e-7 here); a sliver quadprog calls empty, it solves a scale below
    rtol = 1e-2 if shrink else (1e-4 if out.scale < 1.0 else 1e-7)
    assert f_ours <= f_ref * (1 + rtol) + 1e-10, (f_ours, f_ref)
    return True


def reduced_reference(J, xd, S, lo, hi, rates=True):
    """(rates (n,), scale) of the reduced robot (S locked): the LP, then the QP at its scale."""
    keep = [j for j in range(J.shape[1]) if j not in S]
    Js = J[:, keep]
    s = lp_scale(Js, xd, lo[keep], hi[keep])
    out = np.zeros(J.shape[1])
    if not rates:
        return out, s
    v = qp_nearest(Js, s * xd, lo[keep], hi[keep], np.zeros(len(keep)))
    out[keep] = v
    return out, s


def random_case(rng, singular_gap=None):
    """A random task (m, n), box and velocity; with ``singular_gap`` a reduced robot J_S near singular."""
    n = int(rng.integers(3, 8))
    m = int(rng.integers(1, n - 1))
    J = rng.normal(size=(m, n))
    if singular_gap is not None and m >= 1:
        # joint 0 locked leaves J[:, 1:] with σ_min = gap: shrink its last singular value
        U, sv, Vt = np.linalg.svd(J[:, 1:], full_matrices=False)
        sv[-1] = singular_gap * sv[0]
        J[:, 1:] = U @ np.diag(sv) @ Vt
    xd = rng.normal(size=m) * rng.uniform(0.1, 3.0)
    w = rng.uniform(0.05, 2.0, size=n)
    lo, hi = -w * rng.uniform(0.2, 1.0, size=n), w
    return J, xd, lo, hi


@pytest.mark.parametrize("gap", [None, 1e-2, 1e-4, 1e-6, 1e-9, 0.0])
def test_reduced_scale_is_the_lp_scale(gap):
    """Every reduced robot's scale is the LP's largest feasible scale, its rates the QP's, at any σ_min."""
    rng = np.random.default_rng(7)
    for _ in range(60):
        J, xd, lo, hi = random_case(rng, gap)
        n = J.shape[1]
        if projection(J).damped:
            continue
        scales = tolerable_under_limits(J, xd, list(range(n)), bounds=(lo, hi))
        for i in range(n):
            _, s = reduced_reference(J, xd, [i], lo, hi, rates=False)
            if gap is not None and 0.0 < gap < 1e-7:  # κ(J_S) ≥ 1e7: HiGHS itself is off by ~1e-7
                sol = reduced_bounded(J, xd, [i], lo, hi)
                np.testing.assert_allclose(J @ sol.qd, sol.scale * xd, atol=1e-12)
                assert np.all(sol.qd >= lo - 1e-12) and np.all(sol.qd <= hi + 1e-12)
                assert sol.scale == scales[i] and scales[i] >= s - SCALE_ATOL  # feasible, not less
                np.testing.assert_allclose(scales[i], s, atol=1e-6)
            else:
                np.testing.assert_allclose(scales[i], s, atol=SCALE_ATOL)


@pytest.mark.parametrize("gap", [None, 1e-3, 1e-6, 0.0])
def test_jvja_least_norm_targets_exact_reduced_rates(gap):
    """Bounded JVJA (least-norm) equals the QP whose target is the mean of the exact reduced rates."""
    rng = np.random.default_rng(11)
    for _ in range(60):
        J, xd, lo, hi = random_case(rng, gap)
        n = J.shape[1]
        if projection(J).damped:
            continue
        out = resolve_bounded("jvja", J, xd, list(range(n)), bounds=(lo, hi), tolerate=True)
        posts = [reduced_reference(J, xd, [i], lo, hi) for i in range(n)]
        np.testing.assert_allclose(out.reduced_scale, [p[1] for p in posts], atol=SCALE_ATOL)
        c = np.mean([p[0] for p in posts], axis=0)
        s = lp_scale(J, xd, lo, hi)
        np.testing.assert_allclose(out.scale, s, atol=SCALE_ATOL)
        assert assert_matches_qp(J, xd, out, lo, hi, c)


def _check_both_responses(rng, cases):
    """Both responses, random lockable subsets: no raise; scale = LP; rates on the task set in the box."""
    checked = compared = lnva = lnva_compared = undecided = 0
    for _ in range(cases):
        J, xd, lo, hi = random_case(rng, rng.choice([None, 1e-3, 1e-7]))
        n = J.shape[1]
        if projection(J).damped:
            continue
        lockable = sorted(rng.choice(n, size=int(rng.integers(1, n + 1)), replace=False).tolist())
        s = lp_scale(J, xd, lo, hi)
        if s is None:
            undecided += 1
            continue
        for response in ("least_norm", "continuation"):
            out = resolve_bounded(
                "jvja", J, xd, lockable, bounds=(lo, hi), response=response, tolerate=True
            )
            np.testing.assert_allclose(out.scale, s, atol=SCALE_ATOL)
            assert np.all(out.qd >= lo - 1e-12) and np.all(out.qd <= hi + 1e-12)
            np.testing.assert_allclose(J @ out.qd, out.scale * xd, atol=1e-10)
            if response == "continuation":
                compared += assert_continuation_optimal(J, xd, lockable, out, lo, hi)
            checked += 1
        for name in ("lnva",):
            out = resolve_bounded(name, J, xd, bounds=(lo, hi))
            np.testing.assert_allclose(out.scale, s, atol=SCALE_ATOL)
            lnva_compared += assert_matches_qp(J, xd, out, lo, hi, np.zeros(n))
            lnva += 1
    assert compared >= 0.9 * checked / 2  # quadprog solved (nearly) every continuation problem
    assert lnva_compared >= 0.98 * lnva and undecided <= 0.01 * cases
    return checked


@pytest.mark.slow
def test_bounded_solver_converges_seeded():
    """A thousand seeded random and ill-conditioned problems: converged, scale equal to HiGHS's."""
    assert _check_both_responses(np.random.default_rng(2026), 600) > 800


@pytest.mark.slow
def test_bounded_solver_converges_many():
    """Several thousand more problems (slow)."""
    assert _check_both_responses(np.random.default_rng(99), 4000) > 6000


def test_mda_with_its_null_step_at_the_cap_reaches_the_lp_scale():
    """MDA under limits where ∇K is huge (a null step of 1e3-1e4 rad/s): the reference's task scale
    is still the LP's largest (HiGHS), and the compiled step gives the same rates."""
    import fault_tolerance as ft
    from fault_tolerance.control.controller import Controller
    from fault_tolerance.resolution.mda import MDA_MAX_STEP

    arm = ft.load_arm("iiwa", task="position")
    ctrl = Controller(arm, "all", backend="numba", limits=True)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(40):
        q = arm.random_q(rng)
        xd = rng.standard_normal(arm.m)
        xd *= rng.choice([3.0, 10.0, 50.0]) / np.linalg.norm(xd)
        J, (lo, hi) = arm.jacobian(q), arm.rate_bounds(q, ctrl.horizon)
        free = ft.resolve("mda", J, xd, lockable="all", arm=arm, q=q)
        if np.abs(free).max() < 1e-1 * MDA_MAX_STEP:
            continue
        ref = resolve_bounded("mda", J, xd, "all", bounds=(lo, hi), arm=arm, q=q)
        n = J.shape[1]
        lp = linprog(np.r_[np.zeros(n), -1.0], A_eq=np.hstack([J, -xd[:, None]]), b_eq=np.zeros(3),
                     bounds=[*zip(lo, hi, strict=True), (0.0, 1.0)], method="highs")  # fmt: skip
        assert lp.status == 0 and ref.scale == pytest.approx(lp.x[-1], abs=1e-8)
        assert np.all(ref.qd >= lo - 1e-9) and np.all(ref.qd <= hi + 1e-9)
        qd = ctrl.mda(q, xd)
        assert ctrl.last_scale == pytest.approx(ref.scale, abs=1e-8)
        assert np.abs(qd - ref.qd).max() <= 1e-6 * max(1.0, np.abs(ref.qd).max())
        checked += 1
    assert checked >= 1
