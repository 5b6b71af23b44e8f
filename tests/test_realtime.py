"""The real-time Controller against the plain planner: same numbers, same errors, no new outputs."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control.controller import BACKENDS, Controller, available_backends
from fault_tolerance.numerics.linalg import PIVOT_TOL, SIGMA_EPS
from fault_tolerance.resolution import jvja as jvja_module
from fault_tolerance.resolution import mda as mda_module
from fault_tolerance.resolution.indices import rcn_gradient
from fault_tolerance.resolution.jvja import jvja_explicit

AVAILABLE = available_backends()
ATOL = 1e-10


def assert_close(actual, desired, atol=ATOL):
    """``|actual - desired| <= atol`` on rates scaled to unit size.

    JVJA rates reach ~20 rad/s for a unit ẋ where a pivot is ~1e-2, and the planner itself is only
    that accurate relative to them.
    """
    desired = np.asarray(desired)
    scale = max(1.0, float(np.abs(desired).max()))
    np.testing.assert_allclose(actual, desired, rtol=0, atol=atol * scale)


def backend_params():
    """Every backend; those not installed here are skipped (numba is optional)."""
    return [
        pytest.param(b, marks=pytest.mark.skipif(b not in AVAILABLE, reason=f"{b} not installed"))
        for b in BACKENDS
    ]


@pytest.fixture(scope="module", params=backend_params())
def backend(request) -> str:
    return request.param


def _controllers(case, backend, **kw) -> Controller:
    return Controller(case.arm, list(case.lockable), backend=backend, **kw, limits=False)


def _samples(case, draw_q, draw_xdot, rng, k=8, lockable=None):
    return [(draw_q(case, rng, lockable), draw_xdot(rng, case.m)) for _ in range(k)]


def _configs(case, draw_q, rng, k):
    return [draw_q(case, rng) for _ in range(k)]


# -- same numbers as the planner ------------------------------------------------------------------


def test_lnva_matches_resolve(robot, backend, draw_q, draw_xdot, rng):
    """LNVA steps equal ft.resolve('lnva') on the arm's Jacobian (atol 1e-10)."""
    ctrl = _controllers(robot, backend)
    for q, xd in _samples(robot, draw_q, draw_xdot, rng):
        ref = ft.resolve("lnva", robot.arm.jacobian(q), xd)
        assert_close(ctrl.lnva(q, xd), ref)


def test_jvja_matches_resolve_and_explicit(robot, backend, draw_q, draw_xdot, rng):
    """JVJA steps equal ft.resolve('jvja') and the per-scenario pseudo-inverse route (1e-10)."""
    ctrl = _controllers(robot, backend)
    for q, xd in _samples(robot, draw_q, draw_xdot, rng):
        J = robot.arm.jacobian(q)
        qd = ctrl.jvja(q, xd)
        assert_close(qd, ft.resolve("jvja", J, xd, lockable=list(robot.lockable)))
        assert_close(qd, jvja_explicit(J, xd, list(robot.lockable)))
        assert_close(J @ qd, xd)


def test_step_is_the_chosen_method(planar_3r, draw_q, draw_xdot, rng):
    """Controller.step is the method named at construction; JVJA by default."""
    q, xd = draw_q(planar_3r, rng), draw_xdot(rng, 2)
    for method in ("lnva", "jvja", "mda"):  # the built-ins, with their compiled steps
        ctrl = Controller(planar_3r.arm, "all", method=method, limits=False)
        np.testing.assert_array_equal(ctrl.step(q, xd), getattr(ctrl, method)(q, xd))
    default = Controller(planar_3r.arm, limits=False)
    np.testing.assert_array_equal(default.step(q, xd), default.jvja(q, xd))


def test_weighted_and_subset_singletons(robot, backend, draw_q, draw_xdot, rng):
    """Weighted scenarios on part of the joints give ft.resolve's rates (G2 with weights)."""
    lock = list(robot.lockable)[::2] or list(robot.lockable)
    weights = rng.uniform(0.2, 3.0, size=len(lock))
    ctrl = Controller(robot.arm, lock, weights=weights, backend=backend, limits=False)
    for q, xd in _samples(robot, draw_q, draw_xdot, rng, k=5, lockable=lock):
        ref = ft.resolve("jvja", robot.arm.jacobian(q), xd, lockable=lock, weights=weights)
        assert_close(ctrl.jvja(q, xd), ref)


#: Multi-joint scenarios of the Panda's position task (r = 4): pairs, a triple and singletons.
PANDA_MULTI = [(0, 1), (2, 3), (1, 5), (4, 6), (0, 2, 4), (3,), (6,)]


def test_multi_joint_scenarios(panda_position, backend, draw_q, draw_xdot, rng):
    """Multi-joint scenarios (G1, one batched solve per size) give ft.resolve's rates."""
    case, sets = panda_position, PANDA_MULTI
    weights = rng.uniform(0.5, 2.0, size=len(sets))
    ctrl = Controller(case.arm, sets, weights=weights, backend=backend, limits=False)
    for q, xd in _samples(case, draw_q, draw_xdot, rng, k=5, lockable=sets):
        ref = ft.resolve("jvja", case.arm.jacobian(q), xd, lockable=sets, weights=weights)
        assert_close(ctrl.jvja(q, xd), ref)
    uniform = Controller(case.arm, sets, backend=backend, limits=False)
    q, xd = draw_q(case, rng, sets), draw_xdot(rng, case.m)
    assert_close(uniform.jvja(q, xd), ft.resolve("jvja", case.arm.jacobian(q), xd, lockable=sets))


def test_rcn_matches_indices(robot, draw_q, rng):
    """Controller.rcn (one batched eigvalsh) equals ft.rcn for every scenario."""
    ctrl = _controllers(robot, "auto")
    for q in _configs(robot, draw_q, rng, 5):
        k = ctrl.rcn(q)
        np.testing.assert_allclose(
            k, ft.rcn(robot.arm.jacobian(q), list(robot.lockable)), rtol=1e-9, atol=0
        )
        assert np.all(k >= 1.0)


def test_jacobian_derivatives_match_arm(robot, draw_q, rng):
    """The vectorised kinematic Hessian equals Arm.jacobian_derivatives (atol 1e-12)."""
    ctrl = _controllers(robot, "auto")
    for q in _configs(robot, draw_q, rng, 4):
        np.testing.assert_allclose(
            ctrl.jacobian_derivatives(q), robot.arm.jacobian_derivatives(q), rtol=0, atol=1e-12
        )


def test_rcn_gradient_matches_indices(robot, draw_q, rng):
    """The batched ∇K equals indices.rcn_gradient (per-scenario SVDs) to 1e-8 relative."""
    ctrl = _controllers(robot, "auto")
    for q in _configs(robot, draw_q, rng, 4):
        J, dJ = robot.arm.jacobian(q), robot.arm.jacobian_derivatives(q)
        ref = rcn_gradient(J, dJ, list(robot.lockable))
        # eigh of J_S J_Sᵀ (squared singular values) against SVDs: relative, not absolute, accuracy
        np.testing.assert_allclose(
            ctrl.rcn_gradient(J, dJ), ref, rtol=0, atol=1e-8 * max(1.0, np.abs(ref).max())
        )


def test_mda_matches_resolve(robot, draw_q, draw_xdot, rng):
    """MDA steps equal ft.resolve('mda', arm=, q=) with the same gain."""
    ctrl = _controllers(robot, "auto", gain=2e-3)
    for q, xd in _samples(robot, draw_q, draw_xdot, rng, k=4):
        ref = ft.resolve(
            "mda",
            robot.arm.jacobian(q),
            xd,
            lockable=list(robot.lockable),
            arm=robot.arm,
            q=q,
            gain=2e-3,
        )
        np.testing.assert_allclose(
            ctrl.mda(q, xd), ref, rtol=0, atol=1e-8 * max(1.0, np.abs(ref).max())
        )


def test_kernel_as_plain_python(robot, draw_q, draw_xdot, rng):
    """The compiled kernel's source, run as plain Python, gives the planner's LNVA and JVJA."""
    from fault_tolerance.control.fast import step as single_kernel

    ctrl = _controllers(robot, "numpy")
    n = robot.n
    ws, (params, *_) = single_kernel.workspace(ctrl.workspace)
    params[1] = PIVOT_TOL
    kernel = single_kernel.packed_step_kernel.py_func
    for q, xd in _samples(robot, draw_q, draw_xdot, rng, k=3):
        J = robot.arm.jacobian(q)
        out = np.empty(n)
        for jvja, ref in (
            (0, ft.resolve("lnva", J, xd)),
            (1, ft.resolve("jvja", J, xd, lockable=list(robot.lockable))),
        ):
            assert kernel(J, xd, out, ws, jvja) == 0
            assert_close(out, ref)


def test_compiled_kernel_equals_its_plain_python_source(robot, draw_q, draw_xdot, rng):
    """The compiled step (inner kernels inlined) gives its plain-Python source's rates bit for bit."""
    from fault_tolerance.control.fast import step as single_kernel

    ctrl = _controllers(robot, "numpy")
    ws, _ = single_kernel.workspace(ctrl.workspace)
    ws_py = ws.copy()
    compiled, done = single_kernel.compiled_kernel("packed"), 0
    for q, xd in _samples(robot, draw_q, draw_xdot, rng, k=4):
        J = np.ascontiguousarray(robot.arm.jacobian(q))
        for jvja in (0, 1):
            out, out_py = np.empty(robot.n), np.empty(robot.n)
            status = compiled(J, xd, out, ws, jvja)
            assert status == single_kernel.packed_step_kernel.py_func(J, xd, out_py, ws_py, jvja)
            if status == 0:
                np.testing.assert_array_equal(out, out_py)
                done += 1
    assert done > 0


# -- workspace: outputs land in the caller's array -----------------------------------------------


def test_out_is_returned_and_filled(robot, backend, draw_q, draw_xdot, rng):
    """With out= every step writes into that array and returns the same object."""
    ctrl = Controller(robot.arm, list(robot.lockable), backend=backend, limits=False)
    q, xd = draw_q(robot, rng), draw_xdot(rng, robot.m)
    for method in ("lnva", "jvja", "mda"):
        step = getattr(ctrl, method)
        out = np.full(robot.n, np.nan)
        assert step(q, xd, out=out) is out
        assert step(q, xd, out) is out  # positional too
        np.testing.assert_array_equal(out, step(q, xd))
        fresh_a, fresh_b = step(q, xd), step(q, xd)
        assert fresh_a is not fresh_b and fresh_a is not out  # without out=, a new array each call
    k = np.empty(ctrl.f)
    assert ctrl.rcn(q, out=k) is k


def test_out_of_wrong_kind_is_refused(planar_3r, backend, draw_q, draw_xdot, rng):
    """An out of the wrong shape or type raises InvalidInput instead of writing elsewhere."""
    ctrl = Controller(planar_3r.arm, "all", backend=backend, limits=False)
    q, xd = draw_q(planar_3r, rng), draw_xdot(rng, 2)
    for bad in (np.empty(4), np.empty(3, dtype=np.float32), [0.0, 0.0, 0.0]):
        with pytest.raises(ft.InvalidInput, match="out must be"):
            ctrl.jvja(q, xd, out=bad)


# -- singularities, intolerable scenarios, bad input -----------------------------------------

#: Configurations where J drops rank (σ_min < 1e-8): the step must fall back to the damped planner.
SINGULAR = {
    "planar_3r": [0.3, 0.0, 0.0],
    "powercube_3r": [0.3, 0.0, 0.0],
    "spatial_4r": [0.3, 0.2, 0.1, 0.0],
    "panda_pose": [0.0] * 7,
    "panda_position": [
        -0.23914944926027326,
        1.1778029750135073,
        0.4616453332837751,
        -0.4670024236530157,
        0.0,
        2.957079179955638,
        -0.5882414567459997,
    ],
}


def test_singular_configurations_give_finite_damped_rates(robot, backend, draw_xdot, rng):
    """At a singular J the rates are finite and equal the planner's damped ones."""
    q = np.array(SINGULAR[robot.id])
    J = robot.arm.jacobian(q)
    assert np.linalg.svd(J, compute_uv=False)[-1] < 1e-8 < SIGMA_EPS
    ctrl = Controller(robot.arm, list(robot.lockable), backend=backend, limits=False)
    for _ in range(3):
        xd = draw_xdot(rng, robot.m)
        assert_close(ctrl.lnva(q, xd), ft.resolve("lnva", J, xd))
        try:
            ref = ft.resolve(
                "jvja", J, xd, lockable=list(robot.lockable), joint_names=robot.arm.joint_names
            )
        except ft.IntolerableFailure as err:
            with pytest.raises(ft.IntolerableFailure) as got:
                ctrl.jvja(q, xd)
            assert got.value.joints == err.joints
            continue
        qd = ctrl.jvja(q, xd)
        assert np.all(np.isfinite(qd))
        assert_close(qd, ref)
        assert np.all(np.isfinite(ctrl.mda(q, xd)))
    assert ctrl.fallbacks > 0


def test_near_singular_steps_are_finite(robot, backend, draw_xdot, rng):
    """Approaching a singularity along a line of configurations, every rate stays finite."""
    q1 = np.array(SINGULAR[robot.id])
    q0 = q1 + rng.uniform(-0.3, 0.3, size=robot.n)
    ctrl = Controller(robot.arm, list(robot.lockable), backend=backend, limits=False)
    xd = draw_xdot(rng, robot.m)
    for t in np.linspace(0.9, 1.0, 21):
        q = (1 - t) * q0 + t * q1
        assert np.all(np.isfinite(ctrl.lnva(q, xd)))
        try:
            assert np.all(np.isfinite(ctrl.jvja(q, xd)))
        except ft.IntolerableFailure:
            pass


def test_intolerable_scenario_raises_like_the_planner(spatial_4r, backend, draw_xdot, rng):
    """Joint 4 of the spatial 4R is intolerable: the step raises IntolerableFailure naming it."""
    ctrl = Controller(spatial_4r.arm, "all", backend=backend, limits=False)
    q = np.array([0.3, -0.4, 0.5, 1.1])
    xd = draw_xdot(rng, 3)
    with pytest.raises(ft.IntolerableFailure) as ref:
        ft.resolve(
            "jvja",
            spatial_4r.arm.jacobian(q),
            xd,
            lockable="all",
            joint_names=spatial_4r.arm.joint_names,
        )
    with pytest.raises(ft.IntolerableFailure) as got:
        ctrl.jvja(q, xd)
    assert got.value.joints == ref.value.joints == ["joint4"]


def test_tolerate_damps_pivots_like_the_planner(spatial_4r, backend, draw_q, draw_xdot, rng):
    """With tolerate=True an intolerable scenario gets planner.jvja(tolerate=True)'s rates."""
    ctrl = Controller(spatial_4r.arm, "all", tolerate=True, backend=backend, limits=False)
    for _ in range(3):
        q, xd = draw_q(spatial_4r, rng), draw_xdot(rng, 3)
        J = spatial_4r.arm.jacobian(q)
        qd = ctrl.jvja(q, xd)
        assert np.all(np.isfinite(qd))
        assert_close(qd, jvja_module.jvja(J, xd, "all", tolerate=True))
    # away from small pivots the fast path is taken and equals the plain JVJA
    ctrl = Controller(
        spatial_4r.arm, list(spatial_4r.lockable), tolerate=True, backend=backend, limits=False
    )
    q, xd = draw_q(spatial_4r, rng), draw_xdot(rng, 3)
    lock = list(spatial_4r.lockable)
    ref = ft.resolve("jvja", spatial_4r.arm.jacobian(q), xd, lockable=lock)
    assert_close(ctrl.jvja(q, xd), ref)
    assert ctrl.fallbacks == 0


def test_mda_step_is_capped_like_the_planner(robot, draw_q, draw_xdot, rng):
    """A huge MDA gain is capped at max_step, as planner.mda caps it."""
    ctrl = _controllers(robot, "auto", gain=1e3, max_step=0.25)
    q, xd = draw_q(robot, rng), draw_xdot(rng, robot.m)
    ref = mda_module.mda(
        robot.arm.jacobian(q), xd, list(robot.lockable), arm=robot.arm, q=q, gain=1e3, max_step=0.25
    )
    qd = ctrl.mda(q, xd)
    assert_close(qd, ref, atol=1e-9)
    assert np.linalg.norm(qd - ctrl.lnva(q, xd)) <= 0.25 + 1e-12


def test_bad_input_is_named(planar_3r, backend, draw_q, rng):
    """Wrong shapes and non-finite values raise InvalidInput saying which argument is wrong."""
    ctrl = Controller(planar_3r.arm, "all", backend=backend, limits=False)
    q = draw_q(planar_3r, rng)
    with pytest.raises(ft.InvalidInput, match="xdot"):
        ctrl.jvja(q, np.zeros(3))
    with pytest.raises(ft.InvalidInput, match="q has shape"):
        ctrl.lnva(np.zeros(4), np.zeros(2))
    with pytest.raises(ft.InvalidInput, match="finite"):
        ctrl.jvja(q, np.array([np.nan, 0.0]))
    with pytest.raises(ft.InvalidInput, match="finite"):
        ctrl.lnva(np.array([np.nan, 0.0, 0.0]), np.zeros(2))


def test_constructor_validation(planar_3r):
    """Unknown methods and backends, bad gains and non-redundant tasks are refused."""
    arm = planar_3r.arm
    with pytest.raises(ft.InvalidInput, match="method"):
        Controller(arm, method="fastest", limits=False)
    with pytest.raises(ft.InvalidInput, match="backend"):
        Controller(arm, backend="cuda", limits=False)
    with pytest.raises(ft.InvalidInput, match="gain"):
        Controller(arm, gain=-1.0, limits=False)
    with pytest.raises(ft.InvalidScenario):
        Controller(arm, [(0, 1)], limits=False)  # two joints locked together, but r = 1
    pose = ft.load_arm("planar_3r", task="x,y,rz")  # n = m = 3
    with pytest.raises(ft.InvalidInput, match="redundant"):
        Controller(pose, limits=False)


def test_default_lockable_is_every_joint(planar_3r):
    """lockable=None means every joint, as in ft.resolve."""
    ctrl = Controller(planar_3r.arm, limits=False)
    assert ctrl.scenarios.sets == ((0,), (1,), (2,))
    assert "planar_3r" in repr(ctrl)
