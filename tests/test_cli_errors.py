"""Bad input on the command line: exit code 2, exactly one line on stderr, no traceback.

Every case runs ``python -m fault_tolerance ...`` in a subprocess; the processes are started
together (module fixture) so the module stays fast.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_urdf_safety import billion_laughs, chain3, joint, robot


def _files(root: Path) -> dict[str, str]:
    """Input files the cases refer to, by placeholder name (and ``dir``)."""
    files = {
        "bomb": ("bomb.urdf", billion_laughs()),
        "tree": ("tree.urdf", robot(*chain3(), joint("jx", "base", "l2"))),
        "gripper": (
            "gripper.urdf",
            robot(
                *chain3("palm"),
                joint("fa", "palm", "a", kind="fixed", extra="", axis=None),
                '<link name="a"/>',
                joint("fb", "palm", "b", kind="fixed", extra="", axis=None),
                '<link name="b"/>',
            ),
        ),
        "bad_csv": ("bad.csv", "t,x,y\n0,0.35,0\n0.1,abc,0\n"),
        "a_file": ("a_file", "not a folder"),
        "meshy": (
            "meshy.urdf",
            robot(*chain3()).replace(
                '<link name="base"/>',
                '<link name="base"><visual><geometry><mesh filename='
                '"package://no_pkg/base.stl"/></geometry></visual></link>',
            ),
        ),
    }
    for name, text in files.values():
        (root / name).write_text(text)
    return {key: str(root / name) for key, (name, _) in files.items()} | {"dir": str(root)}


SIM = ["simulate", "--no-progress", "--robot", "planar_3r"]

#: id -> (arguments, a fragment of the one-line message); {name}: a file from _files.
CASES = {
    "unknown_robot": (["simulate", "--robot", "plannar_3r"], "robot 'plannar_3r' is not"),
    "missing_urdf": (["simulate", "--urdf", "{dir}/missing.urdf"], "no such URDF file"),
    "entity_bomb": (["simulate", "--urdf", "{bomb}"], "<!DOCTYPE>"),
    "inspect_entity_bomb": (["inspect", "{bomb}"], "<!DOCTYPE>"),
    "inspect_not_a_tree": (["inspect", "{tree}"], "child of two joints"),
    "tip_not_given": (["simulate", "--urdf", "{gripper}", "--task", "planar"], "leaf links"),
    "unknown_tip": (SIM + ["--tip", "flange"], "frame 'flange' is not in the model"),
    "unknown_joint": (SIM + ["--joints", "joint1,elbow"], "joint 'elbow' is not in the model"),
    "unknown_lockable": (SIM + ["--lockable", "joint1,elbow"], "'elbow' is not an active joint"),
    "duplicate_lockable": (SIM + ["--lockable", "joint1,joint1"], "listed twice"),
    "empty_lockable": (SIM + ["--lockable", ","], "--lockable is empty"),
    "too_many_locked": (SIM + ["--lockable", "joint1+joint2"], "r = 1"),
    "intolerable": (
        ["simulate", "--no-progress", "--robot", "spatial_4r", "--lockable", "joint4"],
        "locking joint4 loses the task",
    ),
    "bad_task_row": (SIM + ["--task", "x,y,yaw"], "task 'x,y,yaw' is not allowed"),
    "dt_zero": (SIM + ["--dt", "0"], "--dt must be a finite number > 0"),
    "dt_negative": (SIM + ["--dt", "-0.001"], "--dt must be a finite number > 0"),
    "dt_not_a_number": (SIM + ["--dt", "fast"], "invalid float value: 'fast'"),
    "q0_wrong_length": (SIM + ["--q0", "0.1,0.2"], "needs shape (3,)"),
    "q0_not_finite": (SIM + ["--q0", "0.1,nan,0.2"], "finite"),
    "x0_out_of_reach": (SIM + ["--x0", "3,0"], "out of reach"),
    "csv_bad_row": (SIM + ["--csv", "{bad_csv}"], "bad.csv:3: a field is not a number"),
    "out_is_a_file": (SIM + ["--out", "{a_file}"], "exists and is not a folder"),
    "unknown_algorithm": (SIM + ["--algorithms", "lnva,fast"], "choose among"),
    "lock_unknown_joint": (
        ["lock", "--no-progress", "--robot", "planar_3r", "--joint", "joint9"],
        "joint 'joint9' is not in the model",
    ),
    "lock_time_outside": (
        ["lock", "--no-progress", "--robot", "planar_3r", "--joint", "joint2", "--at", "7"],
        "lock time must be within",
    ),
    "unknown_robot_workspace": (
        ["workspace", "--robot", "plannar_3r", "--out", "{dir}/ws"],
        "arms that suit `workspace`: ['planar_3r', 'spatial_4r', 'powercube_3r', 'ur5']",
    ),
    "unknown_robot_design": (
        ["design", "--robot", "plannar_3r", "--out", "{dir}/d"],
        "did you mean 'planar_3r'? arms that suit `design`: ['planar_3r', 'powercube_3r']",
    ),
    "lockable_none_simulate": (SIM + ["--lockable", "none"], "`simulate` plans or measures"),
    "lockable_none_lock_jvja": (
        [
            "lock",
            "--no-progress",
            "--robot",
            "planar_3r",
            "--joint",
            "joint2",
            "--lockable",
            "none",
            "--algorithm",
            "jvja",
        ],
        "suits `lock --algorithm lnva`",
    ),
    "unknown_case": (["reproduce", "--cases", "fig5", "--out", "{dir}/rep"], "unknown case(s)"),
    "unknown_command": (["simulat"], "invalid choice: 'simulat'"),
}


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, subprocess.CompletedProcess]:
    """Run every case (and the --debug one) at once; wait for all."""
    root = tmp_path_factory.mktemp("cli_errors")
    keys = _files(root)
    cases = {k: args for k, (args, _) in CASES.items()}
    cases["debug"] = ["--debug", "simulate", "--robot", "plannar_3r"]
    cases["warning"] = ["inspect", "{meshy}", "--task", "planar"]
    procs = {
        key: subprocess.Popen(
            [sys.executable, "-m", "fault_tolerance", *(a.format(**keys) for a in args)],
            cwd=root,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for key, args in cases.items()
    }
    out = {}
    for key, p in procs.items():
        stdout, stderr = p.communicate(timeout=120)
        out[key] = subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)
    return out


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_exits_2_with_one_line_on_stderr(results, case):
    """Exit code 2, exactly one line on stderr naming the problem, no traceback, nothing on stdout."""
    p = results[case]
    assert p.returncode == 2, p.stderr
    assert p.stderr.endswith("\n") and p.stderr.count("\n") == 1, p.stderr
    assert "Traceback" not in p.stderr
    assert CASES[case][1] in p.stderr
    assert p.stderr.startswith("fault-tolerance")
    assert p.stdout == ""


def test_debug_shows_the_traceback(results):
    """With --debug the same bad input shows the traceback ending in the toolkit's error."""
    p = results["debug"]
    assert p.returncode != 0
    assert "Traceback (most recent call last)" in p.stderr
    assert "RobotNotFound: robot 'plannar_3r'" in p.stderr


def test_a_warning_is_one_line_too(results):
    """A URDF whose meshes are missing loads (exit 0) with one warning line on stderr naming the
    file and --package-dir."""
    p = results["warning"]
    assert p.returncode == 0, p.stderr
    assert p.stderr.count("\n") == 1 and p.stderr.startswith("fault-tolerance: warning: ")
    assert "meshy.urdf: 1 mesh file(s) not found" in p.stderr and "--package-dir" in p.stderr
    assert "chain to tip 'tool'" in p.stdout
