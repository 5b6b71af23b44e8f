"""The plainest ``simulate`` / ``lock`` runs from the default start on every redundant listed arm.

Checked for each run: no sample outside the joint limits, no near-singular sample, position error
below 1 mm (orientation error below 1 mrad for tasks with angular rows); and the chosen start is
printed in one line.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import fault_tolerance as ft
from fault_tolerance.cli import main
from fault_tolerance.simulation.run import FLAG_NEAR_SINGULAR, Run

ERROR_TOL = 1e-3  # [m] and [rad]


def _listed_redundant(capsys) -> list[str]:
    """The arms ``fault-tolerance robots`` lists with r >= 1."""
    assert main(["robots"]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = lines[0].split()
    r_col = head.index("r")
    names = []
    for line in lines[1:]:
        cells = line.split()
        if len(cells) > r_col and cells[r_col].isdigit() and int(cells[r_col]) >= 1:
            names.append(cells[0])
    return names


LISTED = ("planar_3r", "spatial_4r", "powercube_3r", "iiwa", "panda", "ur5", "xarm7")


def test_the_listed_redundant_arms_are_the_ones_tested(capsys):
    """Every redundant arm `robots` lists is among those the next test runs."""
    assert set(_listed_redundant(capsys)) <= set(LISTED)


def _assert_run_is_clean(arm, run: Run):
    lo = np.where(np.isfinite(arm.lower), arm.lower, -np.pi)
    hi = np.where(np.isfinite(arm.upper), arm.upper, np.pi)
    assert np.all((run.q >= lo - 1e-9) & (run.q <= hi + 1e-9)), "a sample outside the limits"
    assert not np.any(run.flags & FLAG_NEAR_SINGULAR), "a near-singular sample"
    s = run.summary()
    assert s["tracking_error_max"] < ERROR_TOL
    if any(r in ("rx", "ry", "rz") for r in arm.task):
        assert s["orientation_error_max"] < ERROR_TOL


@pytest.mark.slow
@pytest.mark.parametrize("name", LISTED)
def test_plainest_simulate_runs_from_the_default_start(name, tmp_path, capsys):
    """`simulate --robot NAME` (nothing else) runs every algorithm cleanly from a printed start."""
    out = tmp_path / name
    assert main(["simulate", "--robot", name, "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out.splitlines()
    start_lines = [line for line in printed if line.startswith("start q0 = ")]
    assert len(start_lines) == 1
    arm = ft.load_arm(name)
    for alg in ("lnva", "jvja", "mda"):
        run = Run.load(out / alg)
        _assert_run_is_clean(arm, run)
        q0 = json.loads((out / alg / "summary.json").read_text())["meta"]["q0"]
        np.testing.assert_allclose(run.q[0], q0)


@pytest.mark.parametrize("command", ["simulate", "lock"])
def test_a_start_checked_over_part_of_a_longer_task_says_so(command, capsys):
    """The default start is checked over the task's first CHECK_HORIZON seconds at most: for a
    task 2.5 times as long the start line says that only those were checked, of how long a task;
    for a task within the horizon it claims no such cut."""
    from fault_tolerance.planning.default_start import CHECK_HORIZON

    base = [command, "--robot", "planar_3r", "--no-progress"]
    base += ["--joint", "joint2"] if command == "lock" else ["--algorithms", "jvja"]
    long, short = 2.5 * CHECK_HORIZON, CHECK_HORIZON / 2
    assert main([*base, "--duration", f"{long:g}"]) == 0
    start = [line for line in capsys.readouterr().out.splitlines() if line.startswith("start q0")]
    assert len(start) == 1
    assert f"only its first {CHECK_HORIZON:g} s of the {long:g} s task were checked" in start[0]
    assert main([*base, "--duration", f"{short:g}"]) == 0
    start = [line for line in capsys.readouterr().out.splitlines() if line.startswith("start q0")]
    assert len(start) == 1 and "were checked" not in start[0]


# -- real descriptions (tests/data/robots): the plainest --urdf FILE --tip T ------------------

try:
    from real_arms import ARMS, cli_args, load, path_args
except ImportError:  # the data set is not in this checkout
    ARMS = {}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ARMS))
def test_plainest_urdf_simulate_runs_from_the_default_start(name, tmp_path, capsys):
    """`simulate --urdf FILE --tip T` (plus the manifest's package dirs, xacro args, task and
    joints; no start given) runs every algorithm cleanly from a printed default start."""
    out = tmp_path / name
    argv = ["simulate", *cli_args(name), *path_args(name), "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    printed = capsys.readouterr().out.splitlines()
    assert len([line for line in printed if line.startswith("start q0 = ")]) == 1
    arm = load(name)
    for alg in ("lnva", "jvja", "mda"):
        _assert_run_is_clean(arm, Run.load(out / alg))
