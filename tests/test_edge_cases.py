"""Where the fast path and the reference disagreed: now agree or refuse clearly."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control import lapack_steps as kernels
from fault_tolerance.control.controller import Controller
from fault_tolerance.resolution.mda import MDA_MAX_STEP


def test_numpy_backend_reports_singular_factors_instead_of_raising():
    """numpy's 'Singular matrix' becomes LAPACK's info = 1, so the step falls back (damped)."""
    la = kernels.numpy_linalg()
    assert la.dtrtri(np.array([[1.0, 0.0], [0.0, 0.0]]))[1] == 1
    assert la.dposv(np.array([[1.0, 1.0], [1.0, 1.0]]), np.ones(2))[2] == 1
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend="numpy")
    for q in ([0.3, 0.0, 0.0], [0.3, 1e-9, 0.0], [0.0, 0.0, 0.0]):
        q = np.array(q)
        J, xd = arm.jacobian(q), np.array([0.1, 0.05])
        np.testing.assert_allclose(ctrl.lnva(q, xd), ft.resolve("lnva", J, xd), atol=1e-12)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_mda_keeps_the_capped_step_near_a_singular_reduced_jacobian(backend):
    """J fine, J_S (joint 1 locked, links 2-3 aligned) nearly singular, k_S between 5e3 and 5e5:
    ∇K is huge; the step is capped at max_step as ft.resolve's, not dropped. The paper's unbounded
    MDA step (limits=False): a 10⁴ rad/s cap is far outside the joint limits' rate box."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend=backend, limits=False)
    xd = np.array([0.1, 0.05])
    for q3 in (1e-5, 1e-4, 1e-3):
        q = np.array([0.3, 1.0, q3])
        J = arm.jacobian(q)
        ref = ft.resolve("mda", J, xd, lockable="all", arm=arm, q=q)
        got = ctrl.mda(q, xd)
        a = ft.resolve("lnva", J, xd)
        assert np.linalg.norm(got - a) == pytest.approx(MDA_MAX_STEP, rel=1e-9)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * MDA_MAX_STEP)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_mda_at_a_singular_reduced_jacobian_follows_the_other_scenarios(backend):
    """k_S >= RCN_SINGULAR (q3 <= 1e-6) or J_S exactly singular: that reduced robot adds nothing
    (S1), so the step is the other scenarios' push, far below the cap, in every route alike."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend=backend, limits=False)
    xd = np.array([0.1, 0.05])
    for q3 in (1e-9, 1e-6, 0.0):
        q = np.array([0.3, 1.0, q3])
        J = arm.jacobian(q)
        ref = ft.resolve("mda", J, xd, lockable="all", arm=arm, q=q)
        got = ctrl.mda(q, xd)
        assert np.linalg.norm(got - ft.resolve("lnva", J, xd)) < 1e-3 * MDA_MAX_STEP
        np.testing.assert_allclose(got, ref, rtol=1e-7, atol=1e-9)


def test_weights_whose_sum_overflows_still_give_jvja():
    """Eq. (5) is scale-free: weights near the float64 maximum give the same rates as 1, 1, 1."""
    arm = ft.load_arm("planar_3r")
    q, xd = np.array([0.3, 1.2, 1.0]), np.array([0.1, 0.0])
    J = arm.jacobian(q)
    ref = ft.resolve("jvja", J, xd, lockable="all")
    big = [1e308, 1e308, 1e308]
    with np.errstate(over="ignore"):
        assert not np.isfinite(np.sum(big))
    np.testing.assert_allclose(
        ft.resolve("jvja", J, xd, lockable="all", weights=big), ref, atol=1e-14
    )
    assert not np.allclose(ref, ft.resolve("lnva", J, xd))
    for backend in ("numba", "numpy"):
        ctrl = Controller(arm, "all", weights=big, backend=backend)
        np.testing.assert_allclose(ctrl.jvja(q, xd), ref, atol=1e-12)
    skew = [1e308, 5e307, 1e308]
    np.testing.assert_allclose(
        ft.resolve("jvja", J, xd, lockable="all", weights=skew),
        ft.resolve("jvja", J, xd, lockable="all", weights=[1.0, 0.5, 1.0]),
        atol=1e-14,
    )


def test_jvj_of_huge_rates_is_refused_not_nan():
    J = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, 0.7]])
    xd = np.array([1e200, -3e199])
    qd = ft.resolve("lnva", J, xd)
    with pytest.raises(ft.InvalidInput, match="overflows"):
        ft.jvj(J, xd, qd)
    small = np.array([1e-3, -3e-4])
    assert np.isfinite(ft.jvj(J, small * 1e150, ft.resolve("lnva", J, small * 1e150)))


def test_continuation_response_checks_that_the_rates_track_the_task():
    J = np.array([[1.0, 0.5, 0.2], [0.3, 1.0, 0.7]])
    xd = np.array([0.1, 0.0])
    qd = ft.resolve("jvja", J, xd, response="continuation")
    assert np.isfinite(ft.jvj(J, xd, qd, response="continuation"))
    with pytest.raises(ft.InvalidInput, match="J qd"):
        ft.jvj(J, xd, qd + np.array([0.1, 0.0, 0.0]), response="continuation")
