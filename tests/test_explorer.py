"""The interactive explorer (fault_tolerance.viz.explorer): its state, runs, views and widgets."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

from fault_tolerance.errors import InvalidInput
from fault_tolerance.resolution.registry import get, names
from fault_tolerance.simulation import simulate as simulate_module
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.setup import ServoModel
from fault_tolerance.simulation.simulate import simulate
from fault_tolerance.viz.explorer import CHOICES, Explorer, ShiftedPath, lock_sample

JUMP = re.compile(r"‖q̇_after − q̇_before‖² = ([0-9.eE+-]+) \(rad/s\)²")


@pytest.fixture(scope="module")
def explorer():
    return Explorer("planar_3r", algorithm="jvja", lock_joint="joint2", lock_time=0.3)


def whole_lock_run(ex: Explorer, tau: float = 0.0):
    """The lock run of the explorer's setting, simulated from the start as the lock API does."""
    s = ex.setting
    q0, path = ex.start()
    return simulate(ex.arm, path, s.algorithm, q0=q0, lock_joint=s.lock_joint,
                    lock_time=s.lock_time, servo=ServoModel(tau=tau), **ex._sim(s))  # fmt: skip


def cli_jump(ex: Explorer, *extra: str) -> float:
    """The jump ``fault-tolerance lock`` prints for the explorer's setting (its default start)."""
    s = ex.setting
    argv = [sys.executable, "-m", "fault_tolerance", "lock", "--robot", s.arm, "--joint",
            s.lock_joint, "--at", repr(s.lock_time), "--algorithm", s.algorithm, "--lockable",
            ",".join(s.lockable), "--feedback", "10", "--no-progress", *extra]  # fmt: skip
    p = subprocess.run(argv, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr
    return float(JUMP.search(p.stdout).group(1))


def test_shifted_path_is_the_base_path_later():
    """ShiftedPath gives the base path's x and ẋ at t + offset; an offset past its end raises."""
    base = CirclePath(np.array([0.35, 0.0]), 0.1, 2 * np.pi, 1.0)
    shifted = ShiftedPath(base, 0.3, 0.7)
    ts = np.linspace(0, 0.7, 8)
    X, XD = shifted.sample(ts)
    bX, bXD = base.sample(ts + 0.3)
    np.testing.assert_allclose(X, bX, atol=1e-15)
    np.testing.assert_allclose(XD, bXD, atol=1e-15)
    np.testing.assert_allclose(shifted.x0, base.x(0.3), atol=1e-15)
    with pytest.raises(InvalidInput, match="shift must be within"):
        ShiftedPath(base, 1.0, 0.1)


def test_lock_sample_is_the_first_at_or_after_the_time():
    """The lock falls on the first sample at or after the lock time (as simulate locks)."""
    t = np.arange(11) * 0.1
    assert lock_sample(t, 0.3) == 3
    assert lock_sample(t, 0.31) == 4
    assert lock_sample(t, 0.0) == 0
    assert lock_sample(t, 1.0) == 10


BOUNDED = [n for n in names() if get(n).bounded is not None]
CASES = [(a, t) for a in BOUNDED for t in ([0.0, 0.137, 0.5, 0.999, 1.0] if a == "jvja" else [0.4])]


@pytest.mark.parametrize(("algorithm", "lock_time"), CASES)
def test_replay_from_the_lock_is_the_whole_lock_run(explorer, algorithm, lock_time):
    """The lock run re-played from the lock equals the lock run simulated from the start, for
    every registered resolver (docs/MATH.md (R1)); at the ends it is the whole run."""
    explorer.update(algorithm=algorithm, lock_time=lock_time)
    run, whole = explorer.lock_run, whole_lock_run(explorer)
    for name in ("q", "qd", "qd_cmd", "x", "x_des", "error", "jvj", "jvj_parts", "rcn", "K"):
        np.testing.assert_allclose(getattr(run, name), getattr(whole, name), rtol=0, atol=1e-9,
                                   err_msg=name)  # fmt: skip
    np.testing.assert_array_equal(run.flags, whole.flags)
    mine, theirs = dict(run.meta["lock"]), dict(whole.meta["lock"])
    assert mine.pop("jump") == pytest.approx(theirs.pop("jump"), rel=1e-9) and mine == theirs
    assert explorer.jump == pytest.approx(whole.summary()["jump_at_lock"], rel=1e-9)


def test_moving_the_lock_time_runs_only_the_rest_and_caches(explorer, monkeypatch):
    """A new lock time simulates from the lock sample on only; a time seen before runs nothing."""
    explorer.update(algorithm="jvja", lock_time=0.2)
    calls = []
    original = simulate_module.simulate

    def counting(arm, path, algorithm, **kw):
        calls.append((path.duration, kw.get("lock_time")))
        return original(arm, path, algorithm, **kw)

    monkeypatch.setattr(simulate_module, "simulate", counting)
    explorer.update(lock_time=0.6)
    assert len(calls) == 1
    assert calls[0] == (pytest.approx(0.4, abs=1e-9), 0.0)  # the 0.4 s after the lock
    explorer.update(lock_time=0.2)
    explorer.update(lock_time=0.6)
    assert len(calls) == 1  # both runs are cached


def test_algorithms_are_the_registry_s(explorer):
    """The algorithms offered are the registered resolvers that honour joint limits, all of them."""
    from fault_tolerance.simulation.simulate import PATH_PLANNERS

    assert set(explorer.algorithms) == set(BOUNDED) | set(PATH_PLANNERS)
    assert "global" in explorer.algorithms
    assert "jvja" in explorer.algorithms and "lnva" in explorer.algorithms
    off = Explorer("planar_3r", algorithm="lnva", limits=False)
    assert off.algorithms == (*names(), *PATH_PLANNERS)


def test_unknown_choices_and_values_raise_and_keep_the_state(explorer):
    """An unknown choice or value raises InvalidInput naming the allowed ones; nothing changes."""
    before = explorer.setting
    cases = [
        ({"speed": 2}, str(list(CHOICES))),
        ({"algorithm": "nope"}, "is not one of"),
        ({"lock_joint": "joint9"}, "lockable joints"),
        ({"lockable": ["joint9"]}, "joint1"),
        ({"lockable": []}, "one or more"),
        ({"lock_time": 5.0}, r"within \[0, 1.0\]"),
        ({"arm": "no_such_arm"}, "planar_3r"),
    ]
    for change, message in cases:
        with pytest.raises(InvalidInput, match=message):
            explorer.update(**change)
        assert explorer.setting == before


def test_the_figure_shows_the_planned_lambda_and_the_lock(explorer):
    """λ and K lines hold the planned run; the marker sits at the lock time at the jump."""
    explorer.update(algorithm="jvja", lock_joint="joint2", lock_time=0.4)
    fig = explorer.figure()
    planned = explorer.planned_run
    np.testing.assert_array_equal(explorer.lines["lambda"].get_ydata(), planned.jvj)
    np.testing.assert_array_equal(explorer.lines["K"].get_ydata(), planned.K)
    assert list(explorer.lines["jump"].get_xdata()) == [0.4]
    assert list(explorer.lines["jump"].get_ydata()) == [pytest.approx(explorer.jump)]
    assert all(list(v.get_xdata()) == [0.4, 0.4] for v in explorer.lines["lock"])
    title = fig._suptitle.get_text()
    assert "joint2 locks at t = 0.400 s" in title and f"{explorer.jump:.4g} (rad/s)²" in title
    assert explorer.png().startswith(b"\x89PNG")


def test_the_jump_is_the_one_the_lock_command_prints(explorer):
    """The explorer's jump at the lock is the number ``fault-tolerance lock`` prints (tau = 0)."""
    explorer.update(algorithm="jvja", lockable=("joint1", "joint2", "joint3"),
                    lock_joint="joint2", lock_time=0.25)  # fmt: skip
    assert cli_jump(explorer, "--tau", "0") == pytest.approx(explorer.jump, rel=5e-4)


def test_a_servo_lag_runs_the_whole_lock_run():
    """With tau > 0 the lock run is the lock API's (servo from the start), the CLI's default."""
    ex = Explorer("planar_3r", algorithm="lnva", lock_joint="joint3", lock_time=0.5, tau=0.05)
    whole = whole_lock_run(ex, tau=0.05)
    np.testing.assert_allclose(ex.lock_run.q, whole.q, rtol=0, atol=1e-12)
    assert ex.jump == pytest.approx(whole.summary()["jump_at_lock"], rel=1e-12)
    assert cli_jump(ex) == pytest.approx(ex.jump, rel=5e-4)  # the CLI's default tau, 0.05 s
    with pytest.raises(InvalidInput, match="tau"):
        Explorer("planar_3r", tau=-1.0)


def test_the_widgets_drive_the_explorer():
    """Setting each widget's value changes the state, the plotted λ, the jump and the scene."""
    pytest.importorskip("ipywidgets")
    ex = Explorer("planar_3r", algorithm="jvja", lock_joint="joint1", lock_time=0.3)
    box = ex.widgets()
    c = ex.widget_controls
    assert box.children and set(CHOICES) <= set(c)
    assert list(c["algorithm"].options) == list(ex.algorithms)
    lam = ex.lines["lambda"].get_ydata().copy()
    c["algorithm"].value = "lnva"
    assert ex.setting.algorithm == "lnva"
    assert not np.array_equal(ex.lines["lambda"].get_ydata(), lam)
    np.testing.assert_array_equal(ex.lines["lambda"].get_ydata(), ex.planned_run.jvj)
    lam = ex.lines["lambda"].get_ydata().copy()
    c["algorithm"].value = "jvja"
    c["lockable"].value = ("joint2", "joint3")
    assert ex.setting.lockable == ("joint2", "joint3")
    assert ex.setting.lock_joint == "joint2" and c["lock_joint"].value == "joint2"
    assert list(c["lock_joint"].options) == ["joint2", "joint3"]
    assert not np.array_equal(ex.lines["lambda"].get_ydata(), lam)
    jump, png = ex.jump, c["figure"].value
    c["lock_time"].value = 0.55
    assert ex.setting.lock_time == pytest.approx(0.55)
    assert ex.jump != jump and c["figure"].value != png
    assert ex.jump == pytest.approx(whole_lock_run(ex).summary()["jump_at_lock"], rel=1e-9)
    c["lock_joint"].value = "joint3"
    assert ex.setting.lock_joint == "joint3" and ex.lock_run.meta["lock"]["joint"] == "joint3"
    assert "planar_3r" in c["scene"].value and "srcdoc" in c["scene"].value
    c["arm"].value = "spatial_4r"
    assert ex.setting.arm == "spatial_4r" and ex.arm.name == "spatial_4r"
    assert list(c["lockable"].options) == ex.arm.joint_names
    assert c["lock_joint"].value in ex.arm.joint_names
    assert "spatial_4r" in c["scene"].value and "planar_3r" not in c["scene"].value
    assert c["lock_time"].max == pytest.approx(float(ex.planned_run.t[-1]))


def test_a_widget_error_is_shown_and_the_state_kept():
    """A value the explorer refuses is reported beside the controls; the state is unchanged."""
    pytest.importorskip("ipywidgets")
    ex = Explorer("planar_3r", algorithm="lnva", lock_time=0.3)
    ex.widgets(scene=False)
    c = ex.widget_controls
    before = ex.setting
    c["lockable"].value = ()
    assert "InvalidInput" in c["message"].value and ex.setting == before
    assert c["lockable"].value == before.lockable


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["panda", "ur5e"])
def test_the_defaults_work_on_real_arms(arm):
    """Panda (example-robot-data) and the UR5e of tests/data: defaults run, the lock is exact."""
    from real_arms import load

    ex = Explorer(load(arm) if arm == "ur5e" else arm, duration=0.3)
    assert ex.setting.lockable and ex.setting.lock_joint in ex.arm.joint_names
    ex.update(lock_time=0.2)
    whole = whole_lock_run(ex)
    np.testing.assert_allclose(ex.lock_run.q, whole.q, rtol=0, atol=1e-9)
    assert np.isfinite(ex.jump) and ex.jump == pytest.approx(whole.summary()["jump_at_lock"])
    assert ex.arm.name in ex.scene_html()


def test_an_arm_by_name_joins_the_arm_control():
    """update(arm=NAME) loads an example-robot-data arm, offers it in the arm control from then on;
    an unknown name raises InvalidInput listing the arms offered."""
    pytest.importorskip("ipywidgets")
    ex = Explorer("planar_3r", algorithm="lnva", duration=0.3)
    ex.widgets(scene=False)
    with pytest.raises(InvalidInput, match="choose one of"):
        ex.update(arm="no_such_robot")
    ex.update(arm="ur5")
    assert ex.setting.arm == "ur5" and "ur5" in ex.arms
    assert ex.widget_controls["arm"].value == "ur5"
    assert list(ex.widget_controls["lockable"].options) == ex.arm.joint_names
    assert ex.lock_run.meta["robot"] == "ur5"
