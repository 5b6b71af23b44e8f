"""The compiled sample of simulate agrees with the reference code (planner, indices) to 1e-9."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.numerics.fast import sample_dense as sd
from fault_tolerance.simulation.fast import sample as sk
from fault_tolerance.simulation.fast.sampler import Sampler
from fault_tolerance.simulation.paths import CirclePath, FunctionPath
from fault_tolerance.simulation.run import ARRAYS
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate

pytest.importorskip("numba")

TOL = 1e-9
#: k_S comes from eigenvalues of J_S J_Sᵀ in both codes: its rounding error grows like ε k_S²
#: (relative), whichever code computes it; rows with a large k_S get that much more room.
EIG = 1e-15


def _same(a, b):
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        if name == "flags":
            np.testing.assert_array_equal(x, y)
            continue
        if name in ("rcn", "K"):
            kmax = b.rcn.max(axis=1) if name == "K" else b.rcn
            np.testing.assert_array_less(np.abs(x - y), (TOL + EIG * kmax**2) * np.abs(y) + 1e-300)
            continue
        scale = max(1.0, float(np.abs(y).max()))
        np.testing.assert_allclose(x, y, rtol=0, atol=TOL * scale, err_msg=name)
    if (a.qd_cmd is None) != (b.qd_cmd is None):
        raise AssertionError("qd_cmd kept in one run only")
    sa, sb = a.summary(), b.summary()
    rel = TOL + EIG * float(b.rcn.max()) ** 2
    assert sa == pytest.approx(sb, rel=TOL, abs=TOL) or all(
        sa[k] == pytest.approx(sb[k], rel=rel if k.startswith("rcn") else TOL, abs=TOL) for k in sb
    )


def _pair(arm, path, alg, **kw):
    """The compiled sample is the paper's step (no joint limits): run both without them."""
    fast = simulate(arm, path, alg, engine="fast", limits=False, **kw)
    ref = simulate(arm, path, alg, engine="reference", limits=False, **kw)
    _same(fast, ref)
    return fast, ref


@pytest.mark.parametrize("alg", ["lnva", "jvja", "mda"])
def test_planar_cases_agree(alg):
    arm = ft.load_arm("planar_3r")
    path = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.3)
    _pair(arm, path, alg, q0=np.array([0.3, 1.2, 1.0]), lockable="all")


@pytest.mark.parametrize("alg", ["lnva", "jvja", "mda"])
def test_spatial_with_feedback_and_weights_agree(alg):
    arm = ft.load_arm("spatial_4r")
    q0 = np.array([0.3, 0.5, 0.9, 0.7])
    x0 = arm.fk(q0)
    path = CirclePath(x0, 0.05, 2 * np.pi, 0.2, rows=(1, 2))
    _pair(arm, path, alg, q0=q0, lockable=[0, 1, 2], weights=[1.0, 2.0, 0.5], feedback_gain=5.0)


def test_pose_task_and_continuation_response_agree():
    arm = ft.load_arm("panda", task="pose")
    q0 = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.8, 0.6])
    x0 = arm.fk(q0)
    path = FunctionPath(lambda t: x0 + 0.02 * np.sin(t) * np.ones(6), 0.05)
    for response in ("least_norm", "continuation"):
        _pair(arm, path, "jvja", q0=q0, lockable="all", response=response, feedback_gain=2.0)


def test_lock_with_servo_agrees():
    arm = ft.load_arm("powercube_3r")
    q0 = np.array([0.4, 0.9, 0.6])
    path = CirclePath(arm.fk(q0), 0.05, np.pi / 3, 0.4, sign=-1.0)
    kw = dict(q0=q0, lockable=["joint3"], lock_joint="joint3", lock_time=0.15)
    _pair(arm, path, "lnva", servo=ServoModel(tau=0.05, accel_limit=50.0), feedback_gain=10, **kw)


def test_near_singular_samples_go_the_reference_way_and_agree():
    """A path through a singularity of J and near-intolerable samples: damped by the reference."""
    arm = ft.load_arm("planar_3r")
    q0 = np.array([0.0, 0.3, 0.3])  # nearly stretched: σ_min small, pivots small on the way
    path = CirclePath(arm.fk(q0), 0.2, 2 * np.pi, 0.3, sign=-1.0)
    fast, _ = _pair(arm, path, "jvja", q0=q0, lockable="all")
    assert fast.flags.any()  # the run did meet damped samples


def test_engine_is_checked():
    arm = ft.load_arm("planar_3r")
    path = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 0.01)
    with pytest.raises(ft.InvalidInput, match="engine"):
        simulate(arm, path, q0=np.array([0.3, 1.2, 1.0]), engine="turbo")
    panda = ft.load_arm("panda", task="position")
    q0 = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.8, 0.6])
    path = CirclePath(panda.fk(q0), 0.01, 2 * np.pi, 0.01)
    with pytest.raises(ft.InvalidInput, match="multi-joint"):
        simulate(panda, path, q0=q0, lockable=[(0, 1), 3], engine="fast", limits=False)


@pytest.fixture
def samplers(monkeypatch):
    """The :class:`~fault_tolerance.simulation.fast.sampler.Sampler` objects simulate builds, in order."""
    from fault_tolerance.simulation.fast import sampler

    built, real = [], sampler.Sampler

    def spy(*args, **kwargs):
        built.append(real(*args, **kwargs))
        return built[-1]

    monkeypatch.setattr(sampler, "Sampler", spy)
    return built


def _bounded_pair(arm, path, alg, **kw):
    """Under joint limits (the default): the compiled sample against the bounded reference code."""
    fast = simulate(arm, path, alg, engine="fast", **kw)
    ref = simulate(arm, path, alg, engine="reference", **kw)
    _same(fast, ref)
    assert fast.meta["limits"]["enabled"]
    return fast, ref


def _count(run, flag):
    return int(np.count_nonzero(run.flags & flag))


def _near_limits(radius: float, omega: float, duration: float):
    """The planar 3R with joints 1 and 2 near their limits and a circle from there."""
    arm = ft.load_arm("planar_3r")
    q0 = np.array([2.9, -2.5, 1.2])
    path = CirclePath(x0=arm.fk(q0), radius=radius, omega=omega, duration=duration, rows=(0, 1))
    return arm, q0, path


@pytest.mark.parametrize("alg", ["lnva", "jvja", "mda"])
def test_bounds_met_before_and_after_a_lock_agree(alg, samplers):
    """Joints near their limits: bounds are met (planned rates, reduced robots' rates) before and
    after the lock; the compiled sample solves those samples by the bounded resolvers."""
    from fault_tolerance.simulation.run import (
        FLAG_BOUND_ACTIVE,
        FLAG_INTOLERABLE_UNDER_LIMITS,
        FLAG_LOCKED,
        FLAG_NEAR_INTOLERABLE,
    )

    arm, q0, path = _near_limits(0.1, 2 * np.pi, 0.6)
    kw = dict(q0=q0, lockable="all", lock_joint="joint3", lock_time=0.3,
              servo=ServoModel(tau=0.05), feedback_gain=10.0)  # fmt: skip
    fast, ref = _bounded_pair(arm, path, alg, **kw)
    assert _count(ref, FLAG_INTOLERABLE_UNDER_LIMITS) > 0  # reduced robots met bounds
    (smp,) = samplers
    assert smp.bounded_samples > 0  # solved here by the bounded resolvers, not by the reference
    # the reference does only the samples whose pivots it damps (near-intolerable) and the lock
    assert smp.reference_samples == _count(ref, FLAG_NEAR_INTOLERABLE)
    if alg == "mda":
        before, after = ref.flags & FLAG_LOCKED == 0, ref.flags & FLAG_LOCKED != 0
        assert np.any(ref.flags[before] & FLAG_BOUND_ACTIVE)  # the planned rates met bounds
        assert np.any(ref.flags[after] & FLAG_BOUND_ACTIVE)  # and the reduced robot's after it
    s, r = fast.summary(), ref.summary()
    for key in ("bound_active_samples", "task_scaled_samples"):
        assert s[key] == r[key]


@pytest.mark.parametrize("alg", ["lnva", "jvja"])
def test_bounded_planned_rates_and_scaled_task_agree(alg, samplers):
    """A fast circle near a limit: the planned rates meet bounds and the task is scaled."""
    from fault_tolerance.simulation.run import FLAG_BOUND_ACTIVE, FLAG_TASK_SCALED

    arm, q0, path = _near_limits(0.15, 8 * np.pi, 0.25)
    fast, ref = _bounded_pair(arm, path, alg, q0=q0, lockable="all", feedback_gain=10.0,
                              lock_joint="joint2", lock_time=0.12)  # fmt: skip
    assert _count(ref, FLAG_BOUND_ACTIVE) > 0 and _count(ref, FLAG_TASK_SCALED) > 0
    assert samplers[0].boxed is not None and samplers[0].boxed.bounded_steps > 0  # the Controller's


@pytest.mark.parametrize("key", ["panda_pose", "chain_7"])
def test_reduced_robots_at_bounds_are_solved_compiled(key, samplers):
    """From the benchmark pool's first posture most samples have a reduced robot whose (G1) rates
    leave the box: the compiled code solves those reduced robots (L4) and the bounded step, and
    the run equals the reference's (limits on: the default)."""
    from fault_tolerance.bench.cases import make_case

    case = make_case(key)
    arm, q0 = case.arm, case.qs[0]
    path = CirclePath(arm.fk(q0)[: arm.m], 0.01, 2 * np.pi, 0.25, rows=(0, 1))
    fast, ref = _bounded_pair(arm, path, "jvja", q0=q0, lockable="all", dt=1e-3)
    (smp,) = samplers
    samples = len(fast.t)
    assert smp.bounded_samples > samples // 2  # most samples meet a bound (a reduced robot's)
    assert smp.reduced_compiled >= smp.bounded_samples  # at least one reduced robot each
    assert smp.reduced_reference == 0  # none left to bounded.reduced_bounded
    assert smp.boxed.bounded_reference_steps == 0  # the bounded step compiled too
    assert smp.reference_samples == 0


@pytest.mark.parametrize("target", [False, True])
def test_compiled_reduced_solve_equals_reduced_bounded(target):
    """boxsolve.reduced_solve against bounded.reduced_bounded: rates and task scale (L4)."""
    from fault_tolerance.control.fast.bounded_solve import reduced_solve, workspace
    from fault_tolerance.control.lapack_steps import TRACE_MAX
    from fault_tolerance.numerics.linalg import PIVOT_EPS
    from fault_tolerance.resolution.bounded import reduced_bounded

    rng = np.random.default_rng(3)
    m, n, solved, scaled = 4, 7, 0, 0
    for _ in range(40):
        J, xd = rng.normal(size=(m, n)), rng.normal(size=m)
        lo, hi = -rng.uniform(0.05, 1.0, n), rng.uniform(0.05, 1.0, n)
        c = rng.normal(size=n) if target else np.zeros(n)
        cols = np.arange(n, dtype=np.int64)
        F, Iw, views = workspace(n, m, cols.reshape(-1, 1).copy(), cols, 1)
        views["p3"][:] = TRACE_MAX, PIVOT_EPS, 0.0
        views["buf"][0], views["buf"][1] = lo, hi
        post, scales, codes = np.zeros((n, n)), np.zeros(n), np.zeros(n, dtype=np.int64)
        assert reduced_solve(J, xd, c, cols, post, scales, codes, F, Iw) == 0
        for t in np.flatnonzero(codes == 0):
            ref = reduced_bounded(J, xd, (t,), lo, hi, target=c if target else None)
            np.testing.assert_allclose(post[t], ref.qd, atol=1e-9)
            assert scales[t] == pytest.approx(ref.scale, abs=1e-9)
            solved, scaled = solved + 1, scaled + (ref.scale < 1 - 1e-9)
    assert solved > 200 and scaled > 20  # the solves ran, and many needed a scaled task


def test_reduced_robots_refused_by_the_compiled_code_take_reduced_bounded(samplers, monkeypatch):
    """Where the compiled code refuses a reduced robot, bounded.reduced_bounded solves it (counted)."""

    def refuse(self, J, xd_cmd, target, todo, lo, hi, post, scales):
        return np.full(len(todo), 3, dtype=np.int64)

    monkeypatch.setattr(Sampler, "_reduced", refuse)  # the class itself (the fixture wraps it)
    monkeypatch.setattr(Sampler, "_target_posts", lambda self, ctrl: None)  # not JVJA's kept rates
    arm, q0, path = _near_limits(0.1, 2 * np.pi, 0.2)
    _bounded_pair(arm, path, "jvja", q0=q0, lockable="all", feedback_gain=10.0)
    (smp,) = samplers
    assert smp.reduced_reference > 0 and smp.reduced_compiled == 0


def test_auto_engine_takes_the_compiled_sample_under_limits(samplers):
    """With limits on, engine='auto' runs the compiled sample (as engine='fast')."""
    built = samplers
    arm = ft.load_arm("planar_3r")
    q0 = np.array([0.3, 1.2, 1.0])
    path = CirclePath(arm.fk(q0), 0.1, 2 * np.pi, 0.05)
    auto = simulate(arm, path, "jvja", q0=q0)
    assert len(built) == 1 and built[0].s.limits
    assert built[0].reference_samples == 0
    fast = simulate(arm, path, "jvja", q0=q0, engine="fast")
    np.testing.assert_array_equal(auto.q, fast.q)
    _same(auto, simulate(arm, path, "jvja", q0=q0, engine="reference"))


def test_continuation_jvja_under_limits_takes_the_reference():
    """JVJA's continuation response under limits is a bounded solve at every sample."""
    arm = ft.load_arm("planar_3r")
    q0 = np.array([0.3, 1.2, 1.0])
    path = CirclePath(arm.fk(q0), 0.1, 2 * np.pi, 0.02)
    with pytest.raises(ft.InvalidInput, match="continuation response under joint limits"):
        simulate(arm, path, "jvja", q0=q0, response="continuation", engine="fast")
    _same(simulate(arm, path, "lnva", q0=q0, response="continuation", engine="fast"),
          simulate(arm, path, "lnva", q0=q0, response="continuation", engine="reference"))  # fmt: skip


def _kernel_tables(arm, lockable):
    """``(params, ws)`` of the sample kernel for ``lockable``, as the Sampler builds them."""
    cw = ft.Controller(arm, lockable, limits=False).workspace
    params = np.zeros(sd.N_PARAMS)
    params[[sk.P_TRACE, sd.P_PIVOT, sk.P_ALPHA]] = 1e6, 1e-4, cw.alpha
    params[[sk.P_RCN_MAX, sk.P_LOCK]] = 1e8, -1
    ws = np.zeros(sk.workspace_size(arm.m, arm.n))
    sk.set_scenarios(ws, arm.m, arm.n, cw.fw)
    return params, ws


def test_plain_python_kernel_matches_the_compiled_one():
    """The kernel is valid Python without numba: same row from ``py_func``; rates as ft.resolve."""
    from fault_tolerance.simulation.setup import HISTORIES, _allocate

    assert sk.COLUMNS == HISTORIES
    arm = ft.load_arm("spatial_4r")
    q = arm.random_q(np.random.default_rng(3))
    J = np.ascontiguousarray(arm.jacobian(q))
    m, n = J.shape
    xd = np.array([0.1, 0.0, 0.05])
    cols, w = np.array([0, 1, 2], dtype=np.int64), np.ones(3)
    params, ws = _kernel_tables(arm, [0, 1, 2])
    params[[sk.P_DT, sk.P_DECAY, sk.P_ACCEL]] = 1e-3, -1.0, np.inf
    rows = []
    for fn in (sk.compiled_sample_kernel(), sk.compiled_sample_kernel().py_func):
        rec = _allocate(1, n, m, 3, 1e-3)
        flag = fn(J, xd, np.zeros(n), np.zeros(n), q.copy(), np.zeros(n), np.zeros(m),
                  np.zeros(m), np.zeros(m), cols, w, np.full(n, np.inf), params, sk.JVJA, 0,
                  rec["_table"], rec["_offsets"], ws.copy(),
                  np.zeros((3, n)), np.zeros(3), np.zeros((4, n)))  # fmt: skip
        assert flag == 0
        rows.append(rec)
    for h in HISTORIES:
        np.testing.assert_allclose(rows[0][h], rows[1][h], rtol=1e-12, atol=1e-14, err_msg=h)
    ref = ft.resolve("jvja", J, xd, lockable=[0, 1, 2])
    np.testing.assert_allclose(rows[0]["qd_cmd"][0], ref, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(rows[0]["rcn"][0], ft.rcn(J, [0, 1, 2]), rtol=1e-10)


@pytest.mark.parametrize("weights", [None, [1.0, 3.0, 0.5, 2.0]])
def test_sample_rates_are_the_compiled_steps(weights):
    """The sample's JVJA rates are the Controller's compiled step's, bit for bit (one compiled
    copy of eq. G2: the sample calls the step's kernels); its LNVA rates J⁺ẋ agree to 1e-12."""
    from fault_tolerance.control.fast.step import step_kernel, workspace
    from fault_tolerance.control.lapack_steps import TRACE_MAX
    from fault_tolerance.simulation.setup import _allocate

    arm, lockable = ft.load_arm("panda", task="position"), [0, 1, 3, 5]
    cw = ft.Controller(arm, lockable, weights=weights, limits=False).workspace
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = arm.random_q(rng)
        J = np.ascontiguousarray(arm.jacobian(q))
        m, n = J.shape
        xd = rng.normal(size=m)
        params = np.zeros(sd.N_PARAMS)
        params[[sk.P_TRACE, sd.P_PIVOT, sd.P_RANK, sk.P_ALPHA]] = (
            TRACE_MAX, cw.pivot_threshold, cw.rank_coef, cw.alpha)  # fmt: skip
        params[[sk.P_RCN_MAX, sk.P_LOCK, sk.P_DT, sk.P_DECAY, sk.P_ACCEL]] = (
            1e8, -1, 1e-3, -1.0, np.inf)  # fmt: skip
        for method, jvja in ((sk.JVJA, 1), (sk.LNVA, 0)):
            ws = np.zeros(sk.workspace_size(m, n))
            sk.set_scenarios(ws, m, n, cw.fw)
            rec = _allocate(1, n, m, len(lockable), 1e-3)
            cols = np.array(lockable, dtype=np.int64)
            flag = sk.compiled_sample_kernel()(
                J, xd, np.zeros(n), np.zeros(n), q.copy(), np.zeros(n), np.zeros(m), np.zeros(m),
                np.zeros(m), cols, np.ones(len(cols)), np.full(n, np.inf), params, method, 0,
                rec["_table"], rec["_offsets"], ws, np.zeros((3, n)), np.zeros(3),
                np.zeros((4, n)))  # fmt: skip
            _, (p4, fw, G, B, c) = workspace(cw)
            out = np.empty(n)
            status = step_kernel(J, xd, out, G, B, c, fw, p4, jvja)
            assert flag >= 0 and status == 0  # generic configurations: both certified
            if jvja:
                assert np.array_equal(rec["qd_cmd"][0], out)
            else:
                np.testing.assert_allclose(rec["qd_cmd"][0], out, rtol=1e-12, atol=1e-15)


def test_kernel_under_limits_checks_the_rate_box():
    """With P_BOUNDED: a wide box gives the unbounded row; a tight one returns BOUNDED (compiled
    and plain Python alike), with the box (L1) of bounded.rate_box in ``buf``."""
    from fault_tolerance.model.joint_limits import rate_box
    from fault_tolerance.simulation.setup import _allocate

    arm = ft.load_arm("spatial_4r")
    q = arm.random_q(np.random.default_rng(3))
    J = np.ascontiguousarray(arm.jacobian(q))
    m, n = J.shape
    xd = np.array([0.1, 0.0, 0.05])
    cols, w = np.array([0, 1, 2], dtype=np.int64), np.ones(3)
    params, ws = _kernel_tables(arm, [0, 1, 2])
    params[[sk.P_DT, sk.P_DECAY, sk.P_ACCEL, sk.P_BOUNDED]] = 1e-3, -1.0, np.inf, 1.0
    rates = ft.resolve("jvja", J, xd, lockable=[0, 1, 2])
    for fn in (sk.compiled_sample_kernel(), sk.compiled_sample_kernel().py_func):
        for speed, expect in ((20.0, 0), (0.5 * np.abs(rates).max(), sk.BOUNDED)):
            lim = np.array([q - 2.0, q + 2.0, np.full(n, speed)])
            rec, buf = _allocate(1, n, m, 3, 1e-3), np.zeros((4, n))
            flag = fn(J, xd, np.zeros(n), np.zeros(n), q.copy(), np.zeros(n), np.zeros(m),
                      np.zeros(m), np.zeros(m), cols, w, np.full(n, np.inf), params, sk.JVJA, 0,
                      rec["_table"], rec["_offsets"], ws.copy(), lim,
                      np.array([1 / 0.05, 0.0, -1.0]), buf)  # fmt: skip
            assert flag == expect
            lo, hi = rate_box(q, lim[0], lim[1], lim[2], 0.05)
            np.testing.assert_allclose(buf[:2], [lo, hi], rtol=1e-14, atol=1e-14)
            if expect == 0:
                np.testing.assert_allclose(rec["qd_cmd"][0], rates, rtol=1e-10, atol=1e-14)


def test_compiled_flag_constants_are_the_runs():
    """The compiled kernels carry copies of run's flags and bounded's tolerance: they must agree."""
    from fault_tolerance.resolution import bounded
    from fault_tolerance.simulation import run
    from fault_tolerance.simulation.fast import sample_limits, sampler

    assert run.FLAG_TASK_SCALED == sampler._TASK_SCALED
    assert sample_limits._FLAG_SERVO_CLIPPED == run.FLAG_SERVO_CLIPPED
    assert (sk._FLAG_LOCKED, sk._FLAG_STEP_LIMITED, sk._FLAG_OVER_SPEED) == (
        run.FLAG_LOCKED,
        run.FLAG_STEP_LIMITED,
        run.FLAG_OVER_SPEED,
    )
    assert sampler.SCALE_TOL == bounded.SCALE_TOL
