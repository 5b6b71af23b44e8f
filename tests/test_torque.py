"""simulation/torque.py: torque-level runs, brakes, saturation, run files."""

from __future__ import annotations

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.errors import InvalidInput
from fault_tolerance.paper.cases import CASES
from fault_tolerance.simulation.torque import DynamicsModel

CASE = CASES["fig2"]
DURATION = 0.3


@pytest.fixture(scope="module")
def start():
    arm = ft.load_arm(CASE.robot)
    return ft.default_start(arm, list(CASE.lockable), x0=np.array(CASE.x0), path=CASE.path()).q0


def _run(start, arm=None, algorithm="jvja", **kw):
    arm = arm or ft.load_arm(CASE.robot)
    opts = dict(q0=start, lockable=list(CASE.lockable), duration=DURATION, engine="reference")
    opts.update(kw)
    return ft.simulate(arm, CASE.path(), algorithm, **opts)


def test_without_lock_or_saturation_the_arm_reproduces_the_plan(start):
    """Exact model, one sub-step, no saturation: the arm's q equals the plan's to 1e-9 (D8)."""
    plan = _run(start, servo=ft.ServoModel(tau=0.0))
    run = _run(start, dynamics=DynamicsModel())
    assert run.summary()["torque_peak_ratio"] < 1.0
    np.testing.assert_allclose(run.q, plan.q, atol=1e-9)
    np.testing.assert_allclose(run.qd[1:], plan.qd[:-1], atol=1e-7)
    np.testing.assert_allclose(run.error, plan.error, atol=1e-9)


def test_torque_saturation_is_respected_sample_by_sample(start):
    """With effort limits of 2 N·m every applied torque stays inside them, and some command does not."""
    arm = ft.load_arm(CASE.robot)
    arm.model.effortLimit[:] = 2.0
    run = _run(start, arm, lock_joint="joint2", lock_time=0.1, dynamics=DynamicsModel())
    assert np.all(np.abs(run.tau) <= 2.0 + 1e-12)
    assert np.any(np.abs(run.tau_cmd) > 2.0)
    s = run.summary()
    assert s["torque_peak_ratio"] == pytest.approx(1.0)
    assert s["torque_saturated_samples"] > 0


def test_ideal_brake_stops_the_joint_at_once_and_loses_energy(start):
    """Ideal brake: the locked joint's rate is 0 from the lock's sample on; λ > 0; ΔT ≤ 0."""
    run = _run(start, lock_joint="joint2", lock_time=0.1, dynamics=True)
    k = int(np.searchsorted(run.t, 0.1 - 1e-12))
    assert abs(run.qd[k - 1, 1]) > 1e-3
    np.testing.assert_array_equal(run.qd[k:, 1], 0.0)
    np.testing.assert_array_equal(run.tau[k:, 1], 0.0)  # its motor is off
    s = run.summary()
    assert s["lock_impulse"] > 0 and s["kinetic_energy_jump"] <= 0
    assert s["torque_jump_max"] > 0 and s["path_error_peak_after_lock"] > 0


def test_finite_brake_decelerates_then_holds(start):
    """A finite brake takes |q̇ᵢ| I / B-like time, impulse B·t; a stronger brake is quicker."""
    lock = dict(lock_joint="joint2", lock_time=0.1)
    weak = _run(start, **lock, dynamics=DynamicsModel(brake_torque=2.0))
    strong = _run(start, **lock, dynamics=DynamicsModel(brake_torque=20.0))
    lw, ls = weak.meta["dynamics"]["lock"], strong.meta["dynamics"]["lock"]
    assert lw["stopped"] and ls["stopped"]
    assert lw["brake_time"] > ls["brake_time"] > 0
    np.testing.assert_allclose(lw["impulse"], 2.0 * lw["brake_time"], rtol=1e-12)
    k_stop = int(np.searchsorted(weak.t, 0.1 + lw["brake_time"])) + 1
    np.testing.assert_array_equal(weak.qd[k_stop:, 1], 0.0)
    assert np.all(np.abs(weak.qd[int(np.searchsorted(weak.t, 0.1)) : k_stop - 1, 1]) > 0)


def test_dynamics_run_saves_and_loads_its_torques(start, tmp_path):
    """run.npz carries tau and tau_cmd; summary.json the torque figures of the contract."""
    run = _run(start, lock_joint="joint3", lock_time=0.1, dynamics=DynamicsModel(brake_torque=5.0))
    run.save(tmp_path / "r")
    back = ft.Run.load(tmp_path / "r")
    np.testing.assert_array_equal(back.tau, run.tau)
    np.testing.assert_array_equal(back.tau_cmd, run.tau_cmd)
    s = back.summary()
    for key in ("torque_jump_max", "torque_peak_ratio", "lock_impulse", "kinetic_energy_jump",
                "path_error_peak_after_lock"):  # fmt: skip
        assert isinstance(s[key], float), key


def test_dynamics_options_are_checked():
    """servo with dynamics, an unknown dynamics value, a bad brake torque: one clear error each."""
    arm = ft.load_arm(CASE.robot)
    with pytest.raises(InvalidInput, match="servo and dynamics"):
        ft.simulate(arm, CASE.path(), q0=np.zeros(3), servo=ft.ServoModel(), dynamics=True)
    with pytest.raises(InvalidInput, match="dynamics must be"):
        ft.simulate(arm, CASE.path(), q0=np.zeros(3), dynamics="yes")
    with pytest.raises(InvalidInput, match="brake torque"):
        DynamicsModel(brake_torque=-1.0)
    with pytest.raises(InvalidInput, match="kd must be finite and >= 0"):
        DynamicsModel(kd=-1.0)
    with pytest.raises(InvalidInput, match="max_substep must be finite and > 0"):
        DynamicsModel(max_substep=0.0)


def test_inertia_weighted_jvja_runs_with_dynamics(start):
    """jvja_inertia runs like the others; for r = 1 (planar 3R) it gives JVJA's rates (D4)."""
    a = _run(start, None, "jvja", lock_joint="joint2", lock_time=0.1, dynamics=True)
    b = _run(start, None, "jvja_inertia", lock_joint="joint2", lock_time=0.1, dynamics=True)
    np.testing.assert_allclose(b.qd_cmd, a.qd_cmd, atol=1e-8)
    assert b.meta["algorithm"] == "jvja_inertia"


def test_replay_page_plots_the_torques_with_their_effort_limits(start, tmp_path):
    """The replay page of a dynamics run draws τ(t) and dashed effort limits in #ft-plots."""
    pytest.importorskip("meshcat")
    from fault_tolerance.viz.page import export_html

    arm = ft.load_arm(CASE.robot)
    run = _run(start, arm, lock_joint="joint2", lock_time=0.1, dynamics=True)
    export_html(run, tmp_path / "replay.html", arm=arm)
    text = (tmp_path / "replay.html").read_text(encoding="utf-8")
    assert "(d) joint torques, dashed: effort limits" in text
    assert text.count('class="ft-effort"') == 2 * arm.n


def test_docs_dynamics_example_runs():
    """docs/dynamics.md's Python example runs as written."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "dynamics.md").read_text()
    block = text.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(block, "docs/dynamics.md", "exec"), {})  # noqa: S102 - our own documentation
