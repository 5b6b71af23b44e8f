"""The lean bounded step (unbounded step + one box check) equals the one-call bounded kernel."""

import numpy as np
import pytest

from fault_tolerance.bench.chain import synthetic_chain
from fault_tolerance.control.controller import Controller
from fault_tolerance.control.fast.bounded_free import free_kernel, free_workspace
from fault_tolerance.control.fast.bounded_solve import bounded_after, bounded_kernel
from fault_tolerance.model.loading import load_arm

pytest.importorskip("numba")


def _arms():
    return [(load_arm("planar_3r"), "all"), (load_arm("panda", task="position"), "all"),
            (synthetic_chain(14), "all")]  # fmt: skip


def _free_setup(k, method):
    """Arm ``k``, its bounded Controller, the box tables and the free kernel's workspace."""
    arm, lockable = _arms()[k]
    ctrl = Controller(arm, lockable, method=method, backend="numba", limits=True)
    cw = ctrl.workspace
    F, I0, views = cw.box_tables
    Iw = I0.copy()
    Iw[4] = 1 if method == "jvja" else 0
    W = free_workspace(cw.n, cw.m, views["p4"], views["fw"], views["lim"], views["prm"],
                       int(Iw[4]), views["cols"])  # fmt: skip
    return arm, ctrl, F, Iw, views, W


@pytest.mark.parametrize("k", range(3))
@pytest.mark.parametrize("method", ["jvja", "lnva"])
def test_free_kernel_status_and_rates_equal_bounded_kernel(k, method):
    """Status, box and rates of the free kernel equal bounded_kernel's on random steps and boxes."""
    arm, ctrl, F, Iw, views, W = _free_setup(k, method)
    rng = np.random.default_rng(7 + k)
    seen = set()
    for _ in range(200):
        q = rng.uniform(arm.lower, arm.upper) * 0.98
        xd = rng.standard_normal(arm.m) * rng.choice([0.01, 0.1, 1.0])
        J = ctrl.jacobian(q).copy()
        o1, o2 = np.empty(arm.n), np.empty(arm.n)
        s1 = bounded_kernel(J, q, xd, o1, F, Iw)
        box = views["buf"][:2].copy()
        s2 = free_kernel(J, q, xd, o2, W, views["state"].copy())
        seen.add(s2)
        assert (s1 == 2) == (s2 == 2)
        if s2 == 0:  # inside: the same rates, no solve
            assert s1 == 0 and views["state"][1] == 0.0
            np.testing.assert_array_equal(o1, o2)
        elif s2 == 1:  # a bound met: the solve from the free kernel's rates is bounded_kernel's
            s3 = bounded_after(J, q, xd, o2, F, Iw)
            assert s3 == s1
            if s1 != 3:
                np.testing.assert_array_equal(o1, o2)
        if s2 != 2:
            h = 4 + 2 * ctrl.workspace.m
            np.testing.assert_array_equal(W[h + 3 : h + 5, : arm.n], box)
    assert {0, 1} <= seen


def test_controller_bounded_step_counts_and_state():
    """A step meeting a bound is counted and sets the state; a free step after it resets the state."""
    arm = load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend="numba", limits=True)
    q = np.array([0.3, 0.5, 0.4])
    ctrl.jvja(q, np.array([5.0, 0.0]))
    assert ctrl.bounded_steps == 1 and ctrl.last_scale < 1.0 and ctrl.last_active.any()
    ctrl.jvja(q, np.array([1e-3, 0.0]))
    assert ctrl.bounded_steps == 1 and ctrl.last_scale == 1.0 and not ctrl.last_active.any()


@pytest.mark.parametrize("k", range(3))
@pytest.mark.parametrize("method", ["jvja", "lnva"])
def test_one_call_step_equals_free_kernel_then_bounded_after(k, method):
    """free_then_bounded's status and rates are the free kernel's, then bounded_after's, bit for bit."""
    from fault_tolerance.control.fast.bounded_solve import free_then_bounded

    arm, ctrl, F, Iw, views, W = _free_setup(k, method)
    np.testing.assert_array_equal(views["free"][Iw[4]], W)  # the Controller's step filled it
    rng = np.random.default_rng(11 + k)
    seen = set()
    for _ in range(200):
        q = rng.uniform(arm.lower, arm.upper) * 0.98
        xd = rng.standard_normal(arm.m) * rng.choice([0.01, 0.1, 1.0, 10.0])
        J = ctrl.jacobian(q).copy()
        o1, o2 = np.empty(arm.n), np.empty(arm.n)
        s1 = free_kernel(J, q, xd, o1, W, views["state"])
        if s1 == 1:
            s1 = {0: 2, 1: 1, 3: 3}[bounded_after(J, q, xd, o1, F, Iw)]
        elif s1 == 2:
            s1 = 3
        state1 = views["state"].copy()
        s2 = free_then_bounded(J, q, xd, o2, F, Iw)
        seen.add(s2)
        assert s1 == s2
        if s2 != 3:
            np.testing.assert_array_equal(o1, o2)
            np.testing.assert_array_equal(state1, views["state"])
    assert {0, 1} <= seen
    assert free_then_bounded(J, q[:-1], xd, o2, F, Iw) == 3  # sizes: the reference route
