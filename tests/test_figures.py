"""plots: a title on every figure, K on a log axis past two decades, the lock zoom and the λ the
lock command prints."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.figures import runs as plots
from fault_tolerance.planning.posture import initial_posture
from fault_tolerance.simulation.paths import CirclePath
from fault_tolerance.simulation.simulate import simulate

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def runs():
    arm = ft.load_arm("planar_3r")
    q0 = initial_posture(arm, [0.35, 0.0]).q
    path = CirclePath([0.35, 0.0], 0.1, 2 * np.pi, 0.5)
    planned = simulate(arm, path, "lnva", q0=q0, lockable=["joint2"])
    k = int(np.argmax(planned.jvj))
    lock = simulate(
        arm,
        path,
        "lnva",
        q0=q0,
        lock_joint="joint2",
        lock_time=float(planned.t[k]),
        feedback_gain=10.0,
    )
    return {"lnva": planned, "jvja": simulate(arm, path, "jvja", q0=q0)}, planned, lock, k


def test_every_figure_has_a_title(runs):
    """Without a title argument each figure gets one naming the robot."""
    cmp, planned, lock, _ = runs
    for fig in (plots.plot_comparison(cmp), plots.plot_lock({"l": lock}), plots.plot_run(lock)):
        assert "planar_3r" in fig._suptitle.get_text()


def test_k_axis_is_log_only_past_two_decades(runs):
    """K of the paper's case spans < 2 decades: linear; scaled to span 4 decades: log."""
    cmp, _, _, _ = runs
    assert plots.plot_comparison(cmp).axes[1].get_yscale() == "linear"
    wild = dataclasses.replace(cmp["lnva"], K=np.geomspace(3.0, 3e4, len(cmp["lnva"].t)))
    assert plots.plot_comparison({"lnva": wild}).axes[1].get_yscale() == "log"
    assert plots.plot_run(wild).axes[2].get_yscale() == "log"


def test_lock_figure_zooms_on_the_lock_and_marks_the_printed_jump(runs):
    """An inset centred on the lock point; the last panel marks the planned λ the CLI prints."""
    _, planned, lock, k = runs
    fig = plots.plot_lock({"joint2 locks": lock}, planned=planned)
    main = fig.axes[0]
    inset = [a for a in main.child_axes if "zoom at" in a.get_title()]
    assert len(inset) == 1
    x0, x1 = inset[0].get_xlim()
    j = int(np.searchsorted(lock.t, lock.meta["lock"]["time"] - 1e-12))
    assert x0 < lock.x[j, 0] < x1 and (x1 - x0) < 0.5 * np.ptp(main.get_xlim())
    printed = f"{plots.planned_jump(planned, float(planned.t[k])):.4g}"
    assert printed == f"{planned.jvj[k]:.4g}"
    labels = [t.get_text() for t in fig.axes[-1].get_legend().get_texts()]
    assert any(label.endswith(f"λ = {printed}") for label in labels), labels
