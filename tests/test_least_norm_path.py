"""The bounded least-norm path (L8) against an independent LP (HiGHS) and QP (quadprog)."""

import numpy as np
import pytest
from scipy.optimize import linprog

import fault_tolerance as ft
from fault_tolerance.bench.chain import synthetic_chain
from fault_tolerance.control.controller import Controller
from fault_tolerance.resolution.bounded import exact_reduced_least_norm
from fault_tolerance.resolution.fast.least_norm_path import (
    SOLVED,
    UNDECIDED,
    VERTEX,
    least_norm_path,
)

SCALE_ATOL = 1e-8
RATE_ATOL = 1e-6


def run_path(J, xd, lo, hi, mask=None, plain=False):
    """``(code, qd, s, held)`` of the path on one problem."""
    m, n = J.shape
    mask = np.ones(n, dtype=np.int64) if mask is None else mask
    qd, act, out = np.zeros(n), np.zeros(n), np.zeros(2)
    ws, wsi, L = np.zeros((8, n + 1)), np.zeros((2, n + 1), dtype=np.int64), np.zeros((m, m))
    fn = least_norm_path.py_func if plain else least_norm_path
    code = fn(np.ascontiguousarray(J), xd, lo, hi, mask, qd, act, ws, wsi, L, out)
    return code, qd, out[0], act != 0.0


def lp_scale(J, xd, lo, hi):
    """Largest s in [0, 1] with J v = s ẋ, lo <= v <= hi (HiGHS); None when HiGHS is undecided."""
    m, n = J.shape
    res = linprog(np.r_[np.zeros(n), -1.0], A_eq=np.hstack([J, -xd[:, None]]), b_eq=np.zeros(m),
                  bounds=[*zip(lo, hi, strict=True), (0.0, 1.0)], method="highs",
                  options={"primal_feasibility_tolerance": 1e-10,
                           "dual_feasibility_tolerance": 1e-10})  # fmt: skip
    return float(res.x[-1]) if res.status == 0 else None


def random_problem(rng, trial):
    m = int(rng.integers(1, 7))
    n = m + int(rng.integers(1, 30))
    J = rng.standard_normal((m, n))
    if trial % 3 == 0:
        J[:, 0] *= 1e-3  # a nearly idle joint
    xd = rng.standard_normal(m) * rng.choice([0.1, 1.0, 10.0, 100.0])
    lo, hi = -rng.uniform(0, 2, n), rng.uniform(0, 2, n)
    if trial % 5 == 0:
        lo[rng.integers(n)] = 0.0  # a joint at its position limit
    mask = np.ones(n, dtype=np.int64)
    if trial % 2:
        mask[rng.integers(n)] = 0  # a locked joint: a reduced robot
    return J, xd, lo, hi, mask


def test_random_problems_equal_lp_and_exact_reference():
    """Decided problems: HiGHS's scale, the exact reference's rates; most problems decided."""
    rng = np.random.default_rng(11)
    decided = compared = 0
    for trial in range(600):
        J, xd, lo, hi, mask = random_problem(rng, trial)
        code, qd, s, held = run_path(J, xd, lo, hi, mask)
        if code == UNDECIDED:
            continue
        assert code == SOLVED or (code == VERTEX and s < 1.0)
        decided += 1
        keep = np.flatnonzero(mask)
        Js = J[:, keep]
        assert np.all(qd[mask == 0] == 0.0)
        assert np.all(qd >= lo - 1e-12) and np.all(qd <= hi + 1e-12)
        assert np.abs(J @ qd - s * xd).max() <= 1e-8 * max(1.0, np.abs(xd).max())
        ref = exact_reduced_least_norm(Js, xd, lo[keep], hi[keep])
        assert s == pytest.approx(ref.scale, abs=SCALE_ATOL)
        assert np.abs(qd[keep] - ref.qd).max() <= RATE_ATOL * max(1.0, np.abs(ref.qd).max())
        lp = lp_scale(Js, xd, lo[keep], hi[keep])
        if lp is not None:
            compared += 1
            assert s == pytest.approx(lp, abs=SCALE_ATOL)
    assert decided >= 0.85 * 600 and compared >= 0.8 * decided, (decided, compared)


def test_plain_python_equals_compiled():
    rng = np.random.default_rng(3)
    for trial in range(40):
        J, xd, lo, hi, mask = random_problem(rng, trial)
        a, b = run_path(J, xd, lo, hi, mask), run_path(J, xd, lo, hi, mask, plain=True)
        assert a[0] == b[0] and a[2] == pytest.approx(b[2], abs=1e-12)
        assert np.allclose(a[1], b[1], atol=1e-12)


def test_rest_outside_the_box_is_undecided_and_zero_task_is_rest():
    J = np.array([[1.0, 1.0, 1.0]])
    lo, hi = np.array([0.1, -1.0, -1.0]), np.ones(3)  # rest violates joint 0's box
    assert run_path(J, np.array([0.5]), lo, hi)[0] == UNDECIDED
    code, qd, s, _ = run_path(J, np.zeros(1), -np.ones(3), np.ones(3))
    assert code == SOLVED and s == 1.0 and not qd.any()


@pytest.mark.parametrize("n", [14, 30])
def test_long_chain_scaled_problems_decided_and_exact(n):
    """The long chains' scaled steps (most joints held): every robot and reduced robot decided."""
    arm = synthetic_chain(n)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(3):
        q = arm.random_q(rng)
        J = arm.jacobian(q)
        lo, hi = arm.rate_bounds(q, 0.05)
        xd = rng.standard_normal(6)
        xd *= 30.0 / np.linalg.norm(xd)  # far out of reach: the task is scaled
        for lock in [None, 0, n // 2, n - 1]:
            mask = np.ones(n, dtype=np.int64)
            if lock is not None:
                mask[lock] = 0
            code, qd, s, held = run_path(J, xd, lo, hi, mask)
            assert code == VERTEX and s < 1.0 and held.sum() >= n - 6
            keep = np.flatnonzero(mask)
            ref = exact_reduced_least_norm(J[:, keep], xd, lo[keep], hi[keep])
            assert s == pytest.approx(ref.scale, abs=SCALE_ATOL)
            assert np.abs(qd[keep] - ref.qd).max() <= RATE_ATOL
            checked += 1
    assert checked == 12


@pytest.mark.parametrize("n", [14, 30])
def test_controller_scaled_steps_on_a_chain_equal_the_reference(n):
    """Controller(limits=True) LNVA, JVJA and MDA on a chain, task scaled: compiled, = resolve_bounded.

    JVJA's reduced robots start from the whole arm's vertex (L9), and JVJA and MDA take that vertex.
    """
    arm = synthetic_chain(n)
    ctrl = Controller(arm, "all", backend="numba", limits=True)
    rng = np.random.default_rng(8)
    for _ in range(3):
        q = arm.random_q(rng)
        xd = rng.standard_normal(6)
        xd *= 20.0 / np.linalg.norm(xd)
        J, box = arm.jacobian(q), arm.rate_bounds(q, ctrl.horizon)
        for name in ("lnva", "jvja", "mda"):
            before = ctrl.bounded_reference_steps
            qd = getattr(ctrl, name)(q, xd).copy()
            assert ctrl.bounded_reference_steps == before  # solved by the compiled step
            kw = {"arm": arm, "q": q} if name == "mda" else {}
            ref = ft.resolve_bounded(name, J, xd, ctrl.scenarios, bounds=box, **kw)
            assert ctrl.last_scale < 1.0
            assert ctrl.last_scale == pytest.approx(ref.scale, abs=SCALE_ATOL)
            assert np.abs(qd - ref.qd).max() <= RATE_ATOL
