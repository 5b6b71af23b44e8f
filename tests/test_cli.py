"""The fault-tolerance command: help, listing, simulate, lock, reproduce."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from fault_tolerance.cli import EXAMPLES, main

COMMANDS = ["robots", "inspect", "simulate", "lock", "reproduce", "replay", "bench"]


def _run(*args, check=True):
    p = subprocess.run(
        [sys.executable, "-m", "fault_tolerance", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if check:
        assert p.returncode == 0, p.stderr
    return p


def test_help_lists_every_subcommand():
    """`fault-tolerance --help` names every subcommand of DESIGN.md."""
    out = _run("--help").stdout
    for cmd in COMMANDS:
        assert cmd in out


@pytest.mark.parametrize("cmd", COMMANDS)
def test_every_subcommand_has_help_with_an_example(cmd, capsys):
    """Each subcommand's --help ends with an example."""
    with pytest.raises(SystemExit) as e:
        main([cmd, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and EXAMPLES[cmd].split("\n")[0] in out


def test_robots_lists_shipped_and_example_arms(capsys):
    """`robots` lists the three shipped arms and example-robot-data arms with DOF, task and r."""
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for name in ("planar_3r", "spatial_4r", "powercube_3r", "panda", "ur5"):
        assert name in out
    line = next(ln for ln in out.splitlines() if ln.startswith("panda "))
    assert " 7 " in line and " 1" in line


def test_inspect_names_the_intolerable_joint(capsys):
    """`inspect` prints the tree and the chain; the 4R's joint4 is intolerable at a regular pose."""
    assert main(["inspect", "planar_3r"]) == 0
    out = capsys.readouterr().out
    assert "joint1 -> joint2 -> joint3" in out and "candidate tip frames" in out
    assert main(["inspect", "spatial_4r"]) == 0
    out = capsys.readouterr().out
    structural = next(ln for ln in out.splitlines() if "random regular configurations" in ln)
    assert structural.endswith(": joint4")


def test_simulate_writes_runs_and_plots(tmp_path, capsys):
    """`simulate --out` writes run.npz, run.csv, summary.json per algorithm and a comparison plot."""
    out = tmp_path / "sim"
    assert (
        main(
            [
                "simulate",
                "--robot",
                "spatial_4r",
                "--duration",
                "0.1",
                "--no-progress",
                "--algorithms",
                "lnva,jvja",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    for alg in ("lnva", "jvja"):
        for f in ("run.npz", "run.csv", "summary.json", "run.png"):
            assert (out / alg / f).exists()
    assert (out / "comparison.png").exists()
    s = json.loads((out / "jvja" / "summary.json").read_text())
    assert s["meta"]["lockable"] == [["joint1"], ["joint2"], ["joint3"]]


def test_simulate_a_user_urdf_from_a_csv_path(tmp_path, capsys):
    """A URDF given by path with a CSV task path runs end to end."""
    from pathlib import Path

    urdf = Path(__file__).resolve().parents[1] / "robots" / "planar_3r.urdf"
    csv = tmp_path / "p.csv"
    csv.write_text("t,x,y\n0,0.35,0\n0.1,0.36,0.01\n0.2,0.37,0.0\n")
    assert (
        main(
            [
                "simulate",
                "--urdf",
                str(urdf),
                "--tip",
                "tool",
                "--task",
                "planar",
                "--csv",
                str(csv),
                "--algorithms",
                "jvja",
                "--no-progress",
            ]
        )
        == 0
    )
    assert "jvja" in capsys.readouterr().out


def test_lock_at_the_largest_jump(tmp_path, capsys):
    """`lock --at max` finds the moment of largest jump and reports the path error."""
    out = tmp_path / "lock"
    assert (
        main(
            [
                "lock",
                "--robot",
                "planar_3r",
                "--joint",
                "joint2",
                "--at",
                "max",
                "--duration",
                "0.3",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "max jump of joint2" in text and "path error peak" in text
    assert (out / "lock.png").exists() and (out / "run.npz").exists()


def test_bad_input_exits_2_with_one_line(capsys):
    """Bad input: exit code 2 and one line on stderr that names the allowed values."""
    assert main(["simulate", "--robot", "planar_3r", "--task", "xyz", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "planar" in err[0] and "rx" in err[0]
    assert main(["simulate", "--robot", "planar_3r", "--algorithms", "fast", "--no-progress"]) == 2
    assert "lnva" in capsys.readouterr().err


@pytest.mark.slow
def test_reproduce_script_runs_quick(tmp_path):
    """scripts/reproduce.py (thin entry point) runs one quick case and exits 0."""
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "scripts" / "reproduce.py"
    p = subprocess.run(
        [
            sys.executable,
            str(script),
            "--out",
            str(tmp_path),
            "--quick",
            "--cases",
            "fig4",
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    assert (
        json.loads((tmp_path / "summary.json").read_text())["cases"]["fig4"]["robot"] == "planar_3r"
    )
