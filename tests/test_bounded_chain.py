"""The Controller's compiled bounded step on long chains, task far out of reach, against the
reference (resolve_bounded) and the exact reduced robots (exact_reduced_least_norm)."""

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.bench.chain import synthetic_chain
from fault_tolerance.control.controller import Controller
from fault_tolerance.resolution.bounded import exact_reduced_least_norm

SCALE_ATOL = 1e-8
RATE_ATOL = 1e-6


@pytest.mark.parametrize("n", [14, 30])
def test_controller_scaled_steps_on_a_chain_equal_the_reference(n):
    """Controller(limits=True) LNVA, JVJA and MDA on a chain, task scaled: = resolve_bounded (LNVA
    and JVJA by the compiled step, MDA, the paper's baseline, by the reference route)."""
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
            by_reference = ctrl.bounded_reference_steps - before
            assert by_reference == (1 if name == "mda" else 0)  # compiled: LNVA and JVJA
            kw = {"arm": arm, "q": q} if name == "mda" else {}
            ref = ft.resolve_bounded(name, J, xd, ctrl.scenarios, bounds=box, **kw)
            assert ctrl.last_scale < 1.0
            assert ctrl.last_scale == pytest.approx(ref.scale, abs=SCALE_ATOL)
            assert np.abs(qd - ref.qd).max() <= RATE_ATOL


@pytest.mark.parametrize("n", [14, 30])
def test_controller_reduced_robots_of_a_scaled_task_equal_the_exact_reference(n):
    """The bounded JVJA step's reduced robots (the rows a simulated jump reads), task scaled."""
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
