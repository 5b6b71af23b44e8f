"""The compiled bounded solve (boxkernel, boxsolve, boxfast) equals the reference and quadprog."""

import os
import subprocess
import sys

import numpy as np
import pytest
import quadprog

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller, available_backends
from fault_tolerance.control.fast.bounded_solve import bounded_rates
from fault_tolerance.errors import InfeasibleBounds
from fault_tolerance.resolution import bounded
from fault_tolerance.resolution import box_qp as boxqp
from fault_tolerance.resolution.fast import box_qp as boxkernel

REL = 1e-6


def qp_ref(c, J, xdot, lo, hi, keep=None):
    """quadprog: min ½‖q̇ − c‖² s.t. J q̇ = ẋ, lo ≤ q̇ ≤ hi over the columns ``keep``."""
    n = J.shape[1]
    keep = np.arange(n) if keep is None else np.asarray(keep)
    k = len(keep)
    C = np.hstack([J[:, keep].T, np.eye(k), -np.eye(k)])
    b = np.concatenate([xdot, lo[keep], -hi[keep]])
    out = np.zeros(n)
    out[keep] = quadprog.solve_qp(np.eye(k), c[keep], C, b, J.shape[0])[0]
    return out


def random_problem(rng, m, n, tight):
    J = rng.normal(size=(m, n))
    xdot = rng.normal(size=m)
    width = np.abs(np.linalg.pinv(J) @ xdot).max() * (tight or 10.0)
    return J, xdot, -rng.uniform(0.2, 1.0, n) * width, rng.uniform(0.2, 1.0, n) * width


def _sets(n, m):
    sets = [(j,) for j in range(n)]
    return sets + [(0, 1)] if n - m >= 2 else sets


def test_nearest_point_on_the_rates_equals_boxqp():
    """solve_box_rates (the rows ±Z_j) against boxqp.solve_box: solved, scaled and empty boxes."""
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(300):
        m, n = [(2, 4), (3, 7), (1, 3), (3, 5)][rng.integers(4)]
        J, xd, lo, hi = random_problem(rng, m, n, rng.choice([0.2, 0.5, 0.9, 3.0]))
        if rng.uniform() < 0.1:  # an empty box: q̇ > 0 makes row 0 of J q̇ positive, ẋ_0 < 0
            lo, hi = 0.1 * np.abs(hi), np.abs(hi)
            J[0], xd[0] = np.abs(J[0]), -abs(xd[0])
        proj = ft.projection(J)
        a, Z = proj.Jpinv @ xd, bounded._null_basis(proj.N)
        qd, act, out = np.zeros(n), np.zeros(n), np.zeros(2)
        ws, wsi, gram = (
            np.zeros((8, n + 1)),
            np.zeros((2, n + 1), dtype=np.int64),
            np.zeros((n + 1, n + 1)),
        )
        mask = np.ones(n, dtype=np.int64)
        code = boxkernel.solve_box_rates(np.zeros(n), a, np.ascontiguousarray(Z), Z.shape[1], lo,
                                         hi, mask, qd, act, ws, wsi, gram, out, 1.0)  # fmt: skip
        try:
            ref = boxqp.solve_box(np.zeros(n), a, Z, lo, hi)
        except InfeasibleBounds:
            assert code == 4
            seen.add("empty")
            continue
        assert code == 0
        assert out[0] == pytest.approx(ref.scale, rel=1e-9)
        assert np.allclose(qd, ref.qd, atol=1e-8 * max(1.0, np.abs(ref.qd).max()))
        if ref.scale == 1.0:
            assert ((act != 0) == ref.active).all()
        assert np.all(qd >= lo - 1e-12) and np.all(qd <= hi + 1e-12)
        seen.add("scaled" if ref.scale < 1 else ("active" if ref.active.any() else "free"))
    assert seen == {"empty", "scaled", "active", "free"}


def test_one_active_row_equals_nearest_rates_bit_for_bit():
    """The one-row shortcut of solve_box_rates decides only what nearest_rates decides, alike."""
    rng = np.random.default_rng(3)
    taken = declined = 0
    for _ in range(400):
        m, n = [(2, 4), (3, 7), (1, 3), (3, 5)][rng.integers(4)]
        J, xd, lo, hi = random_problem(rng, m, n, rng.choice([0.2, 0.5, 0.9, 3.0]))
        proj = ft.projection(J)
        Z = np.ascontiguousarray(bounded._null_basis(proj.N))
        mask = (rng.uniform(size=n) > 0.15).astype(np.int64)
        ws1, ws2 = np.zeros((8, n + 1)), np.zeros((8, n + 1))
        ws1[6, :n] = ws2[6, :n] = proj.Jpinv @ xd
        wsi, gram = np.zeros((2, n + 1), dtype=np.int64), np.zeros((n + 1, n + 1))
        p = boxkernel._one_row_rates(Z, Z.shape[1], lo, hi, mask, ws1)
        code = boxkernel.nearest_rates(Z, Z.shape[1], lo, hi, mask, ws2, wsi[0], wsi[1], gram)
        if p < 0:
            declined += 1
            continue
        taken += 1
        assert code == 0 and wsi[1, 0] == 1 and wsi[0, 0] == p
        np.testing.assert_array_equal(ws1[7, :n], ws2[7, :n])  # the motion Z u, bit for bit
    assert taken >= 10 and declined >= 10  # both branches seen


@pytest.mark.parametrize("weights", [None, "random"])
@pytest.mark.parametrize("tight", [None, 0.9, 0.5, 0.2])
@pytest.mark.parametrize("m,n", [(2, 3), (2, 4), (3, 7), (1, 4), (3, 5)])
def test_compiled_jvja_equals_reference_and_quadprog(m, n, tight, weights):
    rng = np.random.default_rng(11 * m + n + int(10 * (tight or 0)) + (weights is not None))
    for _ in range(12):
        J, xd, lo, hi = random_problem(rng, m, n, tight)
        sets = _sets(n, m)
        w = None if weights is None else rng.uniform(0.5, 2.0, len(sets))
        try:
            ref = ft.resolve_bounded("jvja", J, xd, sets, bounds=(lo, hi), weights=w)
        except InfeasibleBounds:
            assert bounded_rates("jvja", J, xd, sets, lo, hi, weights=w)[0] == 4
            continue
        code, qd, s, active, _ = bounded_rates("jvja", J, xd, sets, lo, hi, weights=w)
        assert code == 0
        assert s == pytest.approx(ref.scale, rel=1e-9)
        assert np.allclose(qd, ref.qd, atol=1e-8 * max(1.0, np.abs(ref.qd).max()))
        if ref.scale == 1.0:
            assert (active == ref.active).all()
        if ref.scale == 1.0 and np.all(ref.reduced_scale == 1.0):  # quadprog solves the same QPs
            ww = np.ones(len(sets)) if w is None else w
            n_ = J.shape[1]
            post = np.array([qp_ref(np.zeros(n_), J, xd, lo, hi, [j for j in range(n_) if j not in S])
                             for S in sets])  # fmt: skip
            c = ww @ post / ww.sum()
            qp = qp_ref(c, J, xd, lo, hi)
            jump_qd = float(ww @ ((post - qd) ** 2).sum(axis=1))
            jump_qp = float(ww @ ((post - qp) ** 2).sum(axis=1))
            assert abs(jump_qd - jump_qp) <= REL * jump_qp


@pytest.mark.parametrize("name", ["lnva", "mda"])
def test_compiled_lnva_mda_equal_reference(name):
    rng = np.random.default_rng(3)
    for _ in range(60):
        m, n = [(2, 4), (3, 7), (1, 3)][rng.integers(3)]
        J, xd, lo, hi = random_problem(rng, m, n, rng.choice([0.3, 0.8, 2.0]))
        unb = None
        opts = {}
        if name == "mda":  # any target in the null space: MDA keeps its unbounded rates' part
            a = np.linalg.pinv(J) @ xd
            unb = a + ft.projection(J).N @ rng.normal(size=n) * np.abs(a).max()
        try:
            if name == "mda":
                ref = bounded.BoundedRates(*_mda_reference(J, xd, unb, lo, hi))
            else:
                ref = ft.resolve_bounded(name, J, xd, bounds=(lo, hi), **opts)
        except InfeasibleBounds:
            assert bounded_rates(name, J, xd, [(0,)], lo, hi, unbounded=unb)[0] == 4
            continue
        code, qd, s, active, _ = bounded_rates(name, J, xd, [(0,)], lo, hi, unbounded=unb)
        assert code == 0
        assert s == pytest.approx(ref.scale, rel=1e-9)
        assert np.allclose(qd, ref.qd, atol=1e-8 * max(1.0, np.abs(ref.qd).max()))


def _mda_reference(J, xd, unb, lo, hi):
    """resolve_bounded's MDA branch for given unbounded rates (its own ``q̇ = a + N(−α∇K)``)."""
    proj = ft.projection(J)
    a = proj.Jpinv @ xd
    if np.all(unb >= lo - boxqp.BOX_TOL) and np.all(unb <= hi + boxqp.BOX_TOL):
        return np.clip(unb, lo, hi), 1.0, np.zeros(len(a), dtype=bool), np.zeros(0)
    sol = boxqp.solve_box(proj.N @ (unb - a), a, bounded._null_basis(proj.N), lo, hi)
    return sol.qd, sol.scale, sol.active, np.zeros(0)


def _near_limits(arm, rng):
    q = arm.random_q(rng)
    for k in rng.choice(arm.n, size=2, replace=False):
        q[k] = arm.upper[k] - rng.uniform(0, 0.01) if rng.uniform() < 0.5 else arm.lower[k] + 0.005
    return q


CONTROLLERS = [
    ("planar_3r", None, "all", None),
    ("spatial_4r", None, ["joint1", "joint2", "joint3"], None),
    ("panda", "position", "all", None),
    ("panda", "position", [(0, 1), (2,), (4, 5), (6,)], None),
    ("panda", "position", "all", [1.0, 2.0, 0.5, 1.0, 3.0, 1.0, 1.0]),
    ("panda", "pose", "all", None),
]


@pytest.mark.parametrize("method", ["lnva", "jvja", "mda"])
@pytest.mark.parametrize("robot,task,lockable,weights", CONTROLLERS)
def test_controller_compiled_step_equals_reference(robot, task, lockable, weights, method):
    if "numba" not in available_backends():
        pytest.skip("numba not installed")
    arm = ft.load_arm(robot, task=task) if task else ft.load_arm(robot)
    ctrl = Controller(arm, lockable, method=method, weights=weights, backend="numba")
    free = Controller(arm, lockable, method=method, weights=weights, limits=False)
    rng = np.random.default_rng(8)
    trials = 12 if method == "mda" else 40
    checked = 0
    for trial in range(trials):
        q = _near_limits(arm, rng) if trial % 3 else arm.random_q(rng)
        J = arm.jacobian(q)
        xd = rng.normal(size=arm.m) * (0.05 if trial % 2 else 0.5)
        opts = {"dJ": arm.jacobian_derivatives(q)} if method == "mda" else {}
        try:
            ref = ft.resolve_bounded(  # the weights are ctrl.scenarios' (lnva, mda take none)
                method, J, xd, ctrl.scenarios, bounds=arm.rate_bounds(q), **opts
            )
        except ft.FaultToleranceError:
            continue
        qd = ctrl.step(q, xd)
        assert np.allclose(qd, ref.qd, atol=1e-8 * max(1.0, np.abs(ref.qd).max())), trial
        if method == "mda":  # the target is the step's own unbounded MDA (its ∇K equals the
            # planner's to ~1e-10; a strongly scaled task amplifies that in s): the reference
            # algorithm on that target
            lo, hi = arm.rate_bounds(q)
            try:
                ref = bounded.BoundedRates(*_mda_reference(J, xd, free.step(q, xd), lo, hi))
            except InfeasibleBounds:  # the reference cycles there (the planner's target solved)
                pass
        assert ctrl.last_scale == pytest.approx(ref.scale, rel=REL)
        if ref.scale == 1.0:
            assert (ctrl.last_active == ref.active).all()
        checked += 1
    compiled = ctrl.bounded_steps - ctrl.bounded_reference_steps
    assert checked > trials // 2, (checked, ctrl.bounded_steps)
    if method == "mda" or not ctrl.scenarios.singletons:  # these take the reference route
        assert compiled == 0 and ctrl.bounded_steps > 0
    else:
        assert compiled > 0


def test_near_singular_reduced_robots_solved_exactly():
    """A reduced Jacobian near its singularity: the compiled step equals the exact reference.

    The compiled solve either solves the reduced robot (L7) or refuses and leaves the step to the
    exact reference; both give the reference's rates and scale.
    """
    arm = ft.load_arm("panda")
    ctrl = Controller(arm, [0, 2, 4, 6], backend="numba")
    rng = np.random.default_rng(4)
    near = 0
    for trial in range(120):
        q = arm.random_q(rng)
        if trial % 2:
            k = rng.integers(arm.n)
            q[k] = arm.upper[k] - rng.uniform(0, 0.02)
        J = arm.jacobian(q)
        xd = rng.normal(size=arm.m) * (0.02 if trial % 3 else 0.5)
        try:
            ref = ft.resolve_bounded("jvja", J, xd, ctrl.scenarios, bounds=arm.rate_bounds(q))
        except ft.FaultToleranceError:
            continue
        bounded_before = ctrl.bounded_steps
        qd = ctrl.step(q, xd)
        assert np.allclose(qd, ref.qd, atol=1e-8 * max(1.0, np.abs(ref.qd).max()))
        assert ctrl.last_scale == pytest.approx(ref.scale, rel=REL)
        smin = min(
            np.linalg.svd(np.delete(J, S, 1), compute_uv=False)[-1] for S in ctrl.scenarios.sets
        )
        if ctrl.bounded_steps > bounded_before and smin < 1e-3:
            near += 1
    assert near >= 5


def test_reference_route_is_taken_and_counted():
    """Near a singularity of J the compiled solve refuses: the reference solves, counted."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend="numba")
    q = np.array([0.0, 1e-7, 1e-7])  # stretched: J singular, the step is damped by the planner
    xd = np.array([0.0, 5.0])
    qd = ctrl.step(q, xd)
    ref = ft.resolve_bounded("jvja", arm.jacobian(q), xd, "all", bounds=arm.rate_bounds(q))
    assert np.allclose(qd, ref.qd)
    assert ctrl.bounded_reference_steps == ctrl.bounded_steps == 1 and ctrl.fallbacks == 1
    q = np.array([0.3, 1.2, 1.0])
    qd = ctrl.step(q, np.array([50.0, 0.0]))  # far out of reach: compiled, scaled
    assert ctrl.bounded_steps == 2 and ctrl.bounded_reference_steps == 1
    assert ctrl.last_scale < 1.0
    ctrl.step(q, np.array([1e-3, 0.0]))  # inside the box: the state is reset
    assert ctrl.last_scale == 1.0 and not ctrl.last_active.any()


def test_plain_python_equals_compiled():
    """The kernels are valid Python: with NUMBA_DISABLE_JIT the same numbers."""
    code = (
        "import numpy as np, fault_tolerance as ft\n"
        "from fault_tolerance.control.fast.bounded_solve import bounded_rates\n"
        "rng = np.random.default_rng(5)\n"
        "out = []\n"
        "for _ in range(6):\n"
        "    J = rng.normal(size=(3, 6)); xd = rng.normal(size=3)\n"
        "    w = np.abs(np.linalg.pinv(J) @ xd).max() * 0.4\n"
        "    lo, hi = -rng.uniform(0.2, 1, 6) * w, rng.uniform(0.2, 1, 6) * w\n"
        "    sets = [(j,) for j in range(6)] + [(0, 1)]\n"
        "    c, qd, s, a, _ = bounded_rates('jvja', J, xd, sets, lo, hi)\n"
        "    out.append([c, s, *qd])\n"
        "print(repr(np.array(out).tolist()))\n"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=300)  # fmt: skip
    plain = np.array(eval(res.stdout))  # noqa: S307 - our own output
    exec_ns: dict = {}
    exec(code.replace("print(", "result = ("), exec_ns)  # noqa: S102 - the same code, compiled
    compiled = np.array(exec_ns["out"])
    assert np.allclose(plain, compiled, atol=1e-12)
    assert (plain[:, 0] == 0).all()


def test_mda_after_a_planner_fallback():
    """MDA near a singularity (the reference damps): checked against the box, solved if needed."""
    arm = ft.load_arm("planar_3r")
    ctrl = Controller(arm, "all", method="mda", backend="numba")
    q = np.array([0.0, 1e-7, 1e-7])
    for xd in (np.array([0.0, 1e-4]), np.array([0.0, 10.0])):
        qd = ctrl.step(q, xd)
        J, dJ = arm.jacobian(q), arm.jacobian_derivatives(q)
        ref = ft.resolve_bounded("mda", J, xd, "all", bounds=arm.rate_bounds(q), dJ=dJ)
        assert np.allclose(qd, ref.qd, atol=1e-9)
        assert ctrl.last_scale == pytest.approx(ref.scale, rel=REL)
        assert ctrl.bounded_steps == ctrl.bounded_reference_steps  # MDA: the reference route
    assert ctrl.bounded_steps >= 1  # damped, 10 m/s needs 4.3 rad/s (the box: 3)


def test_chain_14_full_active_set_compiled():
    """The chain_14 configuration whose reduced robot of joint 8 returned 4 ("no s ≥ 0")
    with 0 inside the box: with r active rows the step direction is z = 0 exactly (its Gram solve
    left a tiny z and a huge step). The compiled step equals the reference, scaled task and all."""
    if "numba" not in available_backends():
        pytest.skip("numba not installed")
    from test_bounded import CHAIN14_Q, CHAIN14_XD

    from fault_tolerance.bench.chain import synthetic_chain

    arm = synthetic_chain(14)
    ctrl = Controller(arm, "all", backend="numba")
    ref = ft.resolve_bounded("jvja", arm.jacobian(CHAIN14_Q), CHAIN14_XD, ctrl.scenarios,
                             bounds=arm.rate_bounds(CHAIN14_Q, ctrl.horizon))  # fmt: skip
    qd = ctrl.step(CHAIN14_Q, CHAIN14_XD)
    assert ctrl.bounded_steps - ctrl.bounded_reference_steps == 1  # the compiled route solved it
    assert np.allclose(qd, ref.qd, atol=1e-8) and ref.scale < 1.0
    assert ctrl.last_scale == pytest.approx(ref.scale, rel=1e-9)


def test_workspace_rows_of_the_free_step_are_adjacent():
    """bounded_kernel takes B, fw, lim and buf as one view of m + 9 rows of n: they must follow
    each other in the workspace in that order."""
    from fault_tolerance.control.fast.bounded_solve import workspace

    n, m = 7, 3
    F, Iw, views = workspace(n, m, np.arange(n, dtype=np.int64).reshape(-1, 1), np.arange(n), 1)
    starts = [views[name].ctypes.data for name in ("B", "fw", "lim", "buf")]
    sizes = [m * n, 2 * n, 3 * n, 4 * n]
    for a, b, size in zip(starts, starts[1:], sizes, strict=False):
        assert b - a == 8 * size
