"""The compiled bounded step (unbounded step + one box check, then the solve) against the reference."""

import numpy as np
import pytest

from fault_tolerance.bench.chain import synthetic_chain
from fault_tolerance.control.controller import Controller
from fault_tolerance.model.loading import load_arm

pytest.importorskip("numba")


def _arms():
    return [(load_arm("planar_3r"), "all"), (load_arm("panda", task="position"), "all"),
            (synthetic_chain(14), "all")]  # fmt: skip


@pytest.mark.parametrize("k", range(3))
@pytest.mark.parametrize("method", ["jvja", "lnva"])
def test_compiled_bounded_step_equals_the_reference_route(k, method):
    """The one-call compiled step (free kernel, then the solve when a bound is met) gives the
    rates, scale and active set of the reference route (numpy backend) on random steps, inside
    and outside the box."""
    arm, lockable = _arms()[k]
    fast = Controller(arm, lockable, method=method, backend="numba", limits=True)
    ref = Controller(arm, lockable, method=method, backend="numpy", limits=True)
    rng = np.random.default_rng(100 + k)
    met = 0
    for _ in range(60):
        q = arm.random_q(rng)
        xd = rng.standard_normal(arm.m) * rng.choice([0.05, 0.5, 5.0])
        try:
            want = ref.step(q, xd)
        except Exception:  # noqa: BLE001 - intolerable or singular here: both must refuse
            with pytest.raises(Exception):  # noqa: B017
                fast.step(q, xd)
            continue
        got = fast.step(q, xd)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-8 * max(1.0, np.abs(want).max()))
        assert fast.last_scale == pytest.approx(ref.last_scale, abs=1e-8)
        met += bool(ref.last_active.any())
    assert met >= 5  # the bounded solve itself was exercised


def test_controller_bounded_step_counts_and_state():
    """A step meeting a bound is counted and sets the state; a free step after it resets the state."""
    arm = load_arm("planar_3r")
    ctrl = Controller(arm, "all", backend="numba", limits=True)
    q = np.array([0.3, 0.5, 0.4])
    ctrl.jvja(q, np.array([5.0, 0.0]))
    assert ctrl.bounded_steps == 1 and ctrl.last_scale < 1.0 and ctrl.last_active.any()
    ctrl.jvja(q, np.array([1e-3, 0.0]))
    assert ctrl.bounded_steps == 1 and ctrl.last_scale == 1.0 and not ctrl.last_active.any()
