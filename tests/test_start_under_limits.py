"""The default start under joint limits: its claim is what the run finds at t = 0."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.planning.default_start import default_path
from fault_tolerance.planning.posture import lockable_scenarios
from fault_tolerance.planning.start_checks import under_limits_at_start
from fault_tolerance.simulation.run import FLAG_INTOLERABLE_UNDER_LIMITS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_arms import ARMS, load  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _arm(name):
    return load(name) if name in ARMS else ft.load_arm(name)


def _flag0(run) -> bool:
    return bool(run.flags[0] & FLAG_INTOLERABLE_UNDER_LIMITS)


@pytest.mark.parametrize(
    "name", ["planar_3r", "spatial_4r", "powercube_3r", "ur5e", "fr3", "kinova"]
)
def test_default_start_is_tolerable_under_limits_and_the_run_agrees(name):
    """The chosen start claims every lockable joint tolerable under limits; its run flags none at t = 0."""
    arm = _arm(name)
    choice = ft.default_start(arm)
    assert choice.under_limits == ()
    assert "also under the joint limits at t = 0" in choice.reason()
    run = choice.runs.get("jvja") or ft.simulate(
        arm, default_path(arm, choice.x0), "jvja", q0=choice.q0
    )
    assert not _flag0(run)
    sc = lockable_scenarios(arm, None)
    assert under_limits_at_start(arm, choice.q0, default_path(arm, choice.x0), sc, {}) == ()


@pytest.fixture(scope="module")
def slow_joint3(tmp_path_factory):
    """The planar 3R with joint3 limited to 0.02 rad/s: some locks cannot keep the task in the box."""
    text = (ROOT / "robots" / "planar_3r.urdf").read_text(encoding="utf-8")
    head, tail = text.rsplit('velocity="3.0"', 1)
    path = tmp_path_factory.mktemp("slow") / "slow3.urdf"
    path.write_text(head + 'velocity="0.02"' + tail, encoding="utf-8")
    return ft.load_arm(str(path), tip="tool", task="planar")


def test_no_start_tolerable_under_limits_is_said_and_matches_the_run(slow_joint3):
    """When no candidate is tolerable under limits the choice names the joints, offers --lockable."""
    arm = slow_joint3
    choice = ft.default_start(arm)
    assert choice.under_limits, "this arm has no start where every lock keeps the task in the box"
    text = choice.reason()
    assert "intolerable under limits" in text
    assert f"--lockable {','.join(choice.lockable_without)}" in text
    assert not set(choice.lockable_without) & set(choice.under_limits)
    assert _flag0(choice.runs["jvja"])  # what the claim says is what the run finds at t = 0
    better = ft.default_start(arm, list(choice.lockable_without))  # the offered --lockable
    assert better.under_limits == ()
    assert not _flag0(better.runs["jvja"])


def test_without_limits_nothing_is_claimed_about_them(slow_joint3):
    """limits=False: the start is not checked against the box and says nothing about it."""
    choice = ft.default_start(slow_joint3, limits=False)
    assert choice.under_limits is None
    assert "joint limits at t = 0" not in choice.reason()


def test_cli_prints_the_claim_the_run_keeps(tmp_path):
    """simulate's printed start line claims tolerance under limits; summary.json has no flag at t = 0."""
    import json
    import subprocess

    out = tmp_path / "run"
    p = subprocess.run(
        [sys.executable, "-m", "fault_tolerance", "simulate", "--robot", "powercube_3r",
         "--algorithms", "jvja", "--duration", "0.2", "--no-progress", "--out", str(out)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "also under the joint limits at t = 0" in p.stdout
    run = ft.Run.load(out / "jvja")
    assert not _flag0(run)
    summary = json.loads((out / "jvja" / "summary.json").read_text())
    assert np.isfinite(run.q).all() and summary
