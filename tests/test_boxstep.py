"""Controller(limits=True): the bounded step equals the bounded planner."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller, available_backends
from fault_tolerance.control.fast import box_check


def _near_limits(arm, rng):
    q = arm.random_q(rng)
    k = rng.integers(arm.n)
    q[k] = arm.upper[k] - rng.uniform(0, 0.02) if rng.uniform() < 0.5 else arm.lower[k] + 0.01
    return q


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("method", ["lnva", "jvja", "mda"])
@pytest.mark.parametrize("robot,lockable", [("planar_3r", "all"), ("panda", [0, 2, 4, 6])])
def test_bounded_step_equals_bounded_planner(robot, lockable, method, backend):
    arm = ft.load_arm(robot)
    ctrl = Controller(arm, lockable, method=method, backend=backend)
    assert ctrl.limits
    rng = np.random.default_rng(4)
    active = fast = 0
    for trial in range(30):
        q = _near_limits(arm, rng) if trial % 2 else arm.random_q(rng)
        J = arm.jacobian(q)
        if np.linalg.svd(J, compute_uv=False)[-1] < 1e-2:
            continue
        xd = rng.normal(size=arm.m) * (0.02 if trial % 3 else 0.5)
        sc = ctrl.scenarios
        try:
            if sc.pivots(ft.projection(J).N).min() < 1e-6:
                continue
        except Exception:
            continue
        qd = ctrl.step(q, xd)
        opts = {"dJ": arm.jacobian_derivatives(q)} if method == "mda" else {}
        ref = ft.resolve_bounded(method, J, xd, sc, bounds=arm.rate_bounds(q), **opts)
        assert np.allclose(qd, ref.qd, atol=1e-9), (trial, qd, ref.qd)
        assert ctrl.last_scale == pytest.approx(ref.scale)
        lo, hi = arm.rate_bounds(q)
        assert np.all(qd >= lo - 1e-12) and np.all(qd <= hi + 1e-12)
        active += bool(ref.active.any())
        fast += not ref.active.any()
    assert active and (
        fast or method == "mda"
    )  # both paths (MDA on random Panda postures: large ∇K)


def test_status_kernels_agree():
    rng = np.random.default_rng(0)
    n = 7
    seen = set()
    for _ in range(50):
        q = rng.uniform(-1, 1, n)
        lower, upper = -np.ones(n), np.ones(n)
        v = np.full(n, 2.0)
        A = rng.normal(size=(3, n))
        P, Q = np.linalg.pinv(A).T, A  # N = I - PᵀQ = I - pinv(A) A, never formed by the kernels
        N = np.eye(n) - P.T @ Q
        c = rng.normal(size=n) * 0.05
        out = rng.normal(size=n) * rng.uniform(0.1, 3)
        cols = np.array([0, 2, 4, 6])
        lo, hi = np.clip((lower - q) * 20.0, -v, v), np.clip((upper - q) * 20.0, -v, v)
        if (out < lo - 1e-9).any() or (out > hi + 1e-9).any():
            want = 1
        else:  # every reduced robot's rates (G1) from the explicit N
            a = out + 0.25 * N @ c
            post = a - (a[cols] / N[cols, cols])[:, None] * N[cols]
            post[np.arange(len(cols)), cols] = 0.0
            want = 2 if ((post < lo - 1e-9).any() or (post > hi + 1e-9).any()) else 0
        res = []
        lim, prm = np.array([lower, upper, v]), np.array([20.0, -0.25])
        for f in (box_check.box_status, box_check.box_status_numpy):
            buf = np.empty((4, n))  # lo, hi, scratch a (n), scratch y (m <= n)
            res.append(
                (f(q, lim, prm, buf, out, P, Q, c, cols, True), buf[0].copy(), buf[1].copy())
            )
        assert res[0][0] == res[1][0] == want
        assert np.allclose(res[0][1], lo) and np.allclose(res[1][1], lo)
        assert np.allclose(res[0][2], hi) and np.allclose(res[1][2], hi)
        seen.add(want)
    assert seen == {0, 1, 2}


def test_limits_false_is_the_paper():
    arm = ft.load_arm("planar_3r")
    q, xd = np.array([0.3, 1.2, 1.0]), np.array([5.0, 0.0])
    fast = Controller(arm, "all", limits=False).step(q, xd)
    assert np.allclose(fast, ft.resolve("jvja", arm.jacobian(q), xd, "all"))
    bounded = Controller(arm, "all").step(q, xd)
    lo, hi = arm.rate_bounds(q)
    assert np.all(bounded <= hi + 1e-12) and not np.allclose(bounded, fast)
