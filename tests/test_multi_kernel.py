"""The compiled multi-joint JVJA step (G1) gives the planner's rates; plain Python too."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.control.controller import Controller
from fault_tolerance.control.fast import multi_step as mk

pytest.importorskip("numba")

PAIRS = [(0, 1), (2, 4), 3, (5, 6)]


@pytest.fixture(scope="module")
def panda():
    return ft.load_arm("panda", task="position")


def test_compiled_multi_joint_step_matches_the_planner(panda):
    rng = np.random.default_rng(11)
    # the unbounded step (limits=False) is what ft.resolve computes without bounds=
    ctrl = Controller(panda, PAIRS, weights=[1.0, 2.0, 0.5, 1.5], backend="numba", limits=False)
    for _ in range(20):
        q, xd = panda.random_q(rng), rng.standard_normal(3)
        J = panda.jacobian(q)
        try:
            ref = ft.resolve("jvja", J, xd, lockable=PAIRS, weights=[1.0, 2.0, 0.5, 1.5])
        except ft.IntolerableFailure:
            with pytest.raises(ft.IntolerableFailure):
                ctrl.jvja(q, xd)
            continue
        np.testing.assert_allclose(ctrl.jvja(q, xd), ref, rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(J @ ctrl.jvja(q, xd), xd, atol=1e-9)
    assert ctrl.jvja.__name__ == "jvja"


def test_plain_python_multi_kernel(panda):
    rng = np.random.default_rng(2)
    q, xd = panda.random_q(rng), rng.standard_normal(3)
    J = np.ascontiguousarray(panda.jacobian(q))
    sets = np.array([[0, 1], [3, -1]], dtype=np.int64)
    wrel = np.array([0.5, 0.5])
    params = np.array([1e6, 1e-9, 0.0])
    outs = []
    for fn in (mk.multi_kernel, mk.multi_kernel.py_func):
        out = np.zeros(7)
        assert fn(J, xd, out, np.zeros(9 + 21 + 7 + 8 + 4), sets, wrel, params) == 0
        outs.append(out)
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-12, atol=1e-14)
    ref = ft.resolve("jvja", J, xd, lockable=[(0, 1), 3])
    np.testing.assert_allclose(outs[0], ref, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("fn", [mk.multi_kernel, mk.multi_kernel.py_func])
def test_a_scenario_is_refused_exactly_below_its_pivot_threshold(panda, fn):
    """Status 2 exactly when ``λ_min(N[S, S])`` of a scenario is below the threshold: the
    Gershgorin discs that skip the shifted Cholesky test never decide otherwise."""
    rng = np.random.default_rng(5)
    sets = np.array([[0, 1], [2, 4], [5, 6], [1, 3]], dtype=np.int64)
    wrel = np.full(4, 0.25)
    checked = 0
    for _ in range(30):
        q, xd = panda.random_q(rng), rng.standard_normal(3)
        J = np.ascontiguousarray(panda.jacobian(q))
        N = ft.nullspace_projector(J)
        lam = min(np.linalg.eigvalsh(N[np.ix_(S, S)])[0] for S in sets)
        for factor, status in ((0.999, 0), (1.001, 2)):
            params = np.array([1e6, lam * factor, 0.0])
            ws = np.zeros(9 + 21 + 7 + 8 + 4)
            assert fn(J, xd, np.zeros(7), ws, sets, wrel, params) == status, (lam, factor)
            checked += 1
    assert checked == 60
