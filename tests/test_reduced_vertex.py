"""A reduced robot's LP vertex from the whole arm's (L9), against HiGHS and the exact reference."""

import numpy as np
import pytest
from test_least_norm_path import RATE_ATOL, SCALE_ATOL, lp_scale

from fault_tolerance.bench.chain import synthetic_chain
from fault_tolerance.resolution.bounded import exact_reduced_least_norm
from fault_tolerance.resolution.fast.least_norm_path import (
    UNDECIDED,
    VERTEX,
    least_norm_path,
    vertex_state,
)
from fault_tolerance.resolution.fast.reduced_vertex import reduced_vertex, whole_basis


def whole_vertex(J, xd, lo, hi):
    """``(code, s, vst, vb)``: the whole arm's path and, at a vertex, its states and held values."""
    m, n = J.shape
    qd, act, out = np.zeros(n), np.zeros(n), np.zeros(2)
    ws, wsi, L = np.zeros((8, n + 1)), np.zeros((2, n + 1), dtype=np.int64), np.zeros((m, m))
    code = least_norm_path(J, xd, lo, hi, np.ones(n, dtype=np.int64), qd, act, ws, wsi, L, out)
    vst, vb = np.zeros(n, dtype=np.int64), np.zeros(n)
    vertex_state(ws, wsi, vst, vb)
    return code, out[0], vst, vb


def run_vertex(J, xd, lo, hi, S, vst, vb, top, plain=False):
    """``(code, qd, s, held)`` of :func:`reduced_vertex` for the locked joints ``S``."""
    m, n = J.shape
    basic0, Binv0, r0 = np.zeros(m, dtype=np.int64), np.zeros((m, m)), np.zeros(m)
    basis = whole_basis.py_func if plain else whole_basis
    if not basis(J, xd, vst, vb, basic0, Binv0, np.zeros((m, m)), r0):
        return UNDECIDED, None, None, None
    vtx = (vst, vb, basic0, Binv0, r0, np.zeros(n, dtype=np.int64), np.zeros(n),
           np.zeros(m, dtype=np.int64), np.zeros((m, m)), np.zeros(m), np.zeros(m), np.zeros(m))  # fmt: skip
    qd, act, out = np.zeros(n), np.zeros(n), np.zeros(2)
    fn = reduced_vertex.py_func if plain else reduced_vertex
    code = fn(J, xd, lo, hi, np.asarray(S, dtype=np.int64), len(S), vtx, top, qd, act, out)
    return code, qd, out[0], act != 0.0


def scaled_problems(n, count, seed):
    """Chain problems whose task is far out of reach in the rate box (the path's vertex)."""
    arm = synthetic_chain(n)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        q = arm.random_q(rng)
        J = np.ascontiguousarray(arm.jacobian(q))
        lo, hi = arm.rate_bounds(q, 0.05)
        xd = rng.standard_normal(6)
        xd *= rng.choice([10.0, 30.0, 100.0]) / np.linalg.norm(xd)
        yield J, xd, lo, hi


@pytest.mark.parametrize("n", [7, 14, 30])
def test_reduced_vertices_equal_lp_and_exact_reference(n):
    """Every decided reduced robot: HiGHS's scale, the exact reference's rates; almost all decided."""
    decided = tried = 0
    for J, xd, lo, hi in scaled_problems(n, 4, n):
        code, top, vst, vb = whole_vertex(J, xd, lo, hi)
        if code != VERTEX:
            continue
        locks = [[i] for i in range(n)] + [[i, (i + 3) % n] for i in range(0, n, 5)]
        for S in locks:
            tried += 1
            code, qd, s, held = run_vertex(J, xd, lo, hi, S, vst, vb, top)
            if code == UNDECIDED:
                continue
            assert code == 0
            decided += 1
            keep = np.setdiff1d(np.arange(n), S)
            assert np.all(qd[S] == 0.0) and s <= top + 1e-12
            assert np.all(qd >= lo - 1e-12) and np.all(qd <= hi + 1e-12)
            assert np.abs(J @ qd - s * xd).max() <= 1e-8 * np.abs(xd).max()
            ref = exact_reduced_least_norm(J[:, keep], xd, lo[keep], hi[keep])
            assert s == pytest.approx(ref.scale, abs=SCALE_ATOL)
            assert np.abs(qd[keep] - ref.qd).max() <= RATE_ATOL * max(1.0, np.abs(ref.qd).max())
            lp = lp_scale(J[:, keep], xd, lo[keep], hi[keep])
            assert lp is None or s == pytest.approx(lp, abs=SCALE_ATOL)
    assert tried >= 2 * n and decided >= 0.9 * tried, (decided, tried)


def test_plain_python_equals_compiled():
    for J, xd, lo, hi in scaled_problems(14, 2, 4):
        code, top, vst, vb = whole_vertex(J, xd, lo, hi)
        assert code == VERTEX
        for S in ([0], [5], [13], [2, 9]):
            a = run_vertex(J, xd, lo, hi, S, vst, vb, top)
            b = run_vertex(J, xd, lo, hi, S, vst, vb, top, plain=True)
            assert a[0] == b[0] == 0 and a[2] == pytest.approx(b[2], abs=1e-12)
            assert np.allclose(a[1], b[1], atol=1e-12)


def test_a_basis_that_is_not_the_vertex_is_undecided():
    """States that are no vertex (too few free joints) are refused, not solved wrongly."""
    J, xd, lo, hi = next(scaled_problems(7, 1, 2))
    code, top, vst, vb = whole_vertex(J, xd, lo, hi)
    assert code == VERTEX
    bad = vst.copy()
    bad[np.flatnonzero(bad == 0)[0]] = 3  # one free joint switched off: m − 2 free columns
    assert run_vertex(J, xd, lo, hi, [6], bad, vb, top)[0] == UNDECIDED


@pytest.mark.parametrize("n", [14, 30])
def test_controller_reduced_robots_at_the_vertex_equal_the_exact_reference(n):
    """The bounded JVJA step's reduced robots (the rows a simulated jump reads), task scaled."""
    from fault_tolerance.control.controller import Controller

    arm = synthetic_chain(n)
    ctrl = Controller(arm, "all", backend="numba", limits=True)
    views = ctrl.workspace.box_tables[2]
    rng = np.random.default_rng(n + 1)
    for _ in range(2):
        q = arm.random_q(rng)
        xd = rng.standard_normal(6)
        xd *= 30.0 / np.linalg.norm(xd)
        before = ctrl.bounded_reference_steps
        ctrl.jvja(q, xd)
        assert ctrl.bounded_reference_steps == before and ctrl.last_scale < 1.0
        J, (lo, hi) = arm.jacobian(q), arm.rate_bounds(q, ctrl.horizon)
        for k, S in enumerate(ctrl.scenarios.sets):
            keep = np.setdiff1d(np.arange(n), S)
            ref = exact_reduced_least_norm(J[:, keep], xd, lo[keep], hi[keep])
            assert views["pscale"][k] == pytest.approx(ref.scale, abs=SCALE_ATOL)
            assert views["psolved"][k] == 1.0 and np.all(views["posts"][k, list(S)] == 0.0)
            assert np.abs(views["posts"][k, keep] - ref.qd).max() <= RATE_ATOL
