"""``simulate --dynamics`` and ``lock --dynamics``: torque figures per algorithm and brake."""

from __future__ import annotations

import json

import pytest

from fault_tolerance.cli import main

LOCK = ["lock", "--robot", "planar_3r", "--joint", "joint2", "--at", "0.2", "--duration", "0.3",
        "--x0", "0.35,0", "--no-progress"]  # fmt: skip


def test_lock_dynamics_reports_every_algorithm_and_both_brakes(tmp_path, capsys):
    """One table row per (algorithm, brake); each run folder's summary.json has the contract keys."""
    out = tmp_path / "lock"
    code = main([*LOCK, "--dynamics", "--algorithms", "lnva,jvja_inertia", "--brake-torque", "5",
                 "--out", str(out)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    for alg in ("lnva", "jvja_inertia"):
        assert f"{alg:13} ideal" in text and f"{alg:13} finite 5 N·m" in text
    for folder in ("lnva_ideal", "lnva_finite", "jvja_inertia_ideal", "jvja_inertia_finite"):
        s = json.loads((out / folder / "summary.json").read_text())["summary"]
        for key in ("torque_jump_max", "torque_peak_ratio", "lock_impulse", "kinetic_energy_jump",
                    "path_error_peak_after_lock"):  # fmt: skip
            assert isinstance(s[key], float), (folder, key)
    meta = json.loads((out / "lnva_finite" / "summary.json").read_text())["meta"]
    assert meta["dynamics"]["brake_torque"] == 5.0


def test_simulate_dynamics_prints_the_peak_torque(capsys):
    """simulate --dynamics adds the peak-torque table."""
    code = main(["simulate", "--robot", "planar_3r", "--x0", "0.35,0", "--duration", "0.2",
                 "--algorithms", "jvja", "--dynamics", "--no-progress"])  # fmt: skip
    assert code == 0
    assert "peak |τ|/τmax" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra, message",
    [(["--kp", "10"], "add --dynamics"), (["--dynamics", "--brake-torque", "-2"], "brake torque")],
)
def test_dynamics_options_are_refused_with_one_line(extra, message, capsys):
    """Dynamics options without --dynamics, and a negative brake torque: exit 2, one line."""
    assert main([*LOCK, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
