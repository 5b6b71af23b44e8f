"""Rough edges a newcomer hits: unknown robots, ``--lockable none``, the
README's bench tables."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import fault_tolerance as ft
from fault_tolerance.cli import main
from fault_tolerance.cli.suits import suited_arms

ROOT = Path(__file__).resolve().parents[1]


def test_unknown_robot_suggests_the_closest_name_and_the_preset_arms():
    """From Python: the closest names and the arms with a preset, not all 80 models."""
    with pytest.raises(ft.RobotNotFound) as err:
        ft.load_arm("pandaa")
    msg = str(err.value)
    assert "did you mean 'panda'?" in msg
    assert "'talos'" not in msg and "'anymal'" not in msg  # legged robots are not offered
    from fault_tolerance.model.catalog import preset_names

    assert err.value.suits == preset_names()


def test_suited_arms_are_those_the_command_runs():
    """Each arm offered for `workspace` / `design` really passes that command's own check."""
    from fault_tolerance.analysis.design.search import design
    from fault_tolerance.analysis.workspace.closed_form import workspace_spec

    assert suited_arms("simulate") == suited_arms(None)
    assert set(suited_arms("design")) == {"planar_3r", "powercube_3r"}
    for name in suited_arms("workspace"):
        workspace_spec(ft.load_arm(name))  # raises for an arm the workspace cannot map
    with pytest.raises(ft.FaultToleranceError, match="planar or position task"):
        workspace_spec(ft.load_arm("panda"))  # a pose task: not offered, and refused
    with pytest.raises(ft.FaultToleranceError, match="design needs a planar 3R"):
        design(ft.load_arm("spatial_4r"))
    assert "spatial_4r" not in suited_arms("design")


def test_robots_all_lists_every_example_robot_data_model(capsys):
    """`robots --all` names the models without a preset too."""
    assert main(["robots", "--all"]) == 0
    out = capsys.readouterr().out
    assert "models without a preset" in out and "talos" in out and "solo12" in out


def test_lockable_none_runs_an_lnva_lock(tmp_path, capsys):
    """`lock --algorithm lnva --lockable none`: rates anticipate no failure; the locking joint's
    jump is measured, and it equals the run with the locking joint named as the lockable one."""
    common = [
        "lock",
        "--robot",
        "planar_3r",
        "--joint",
        "joint2",
        "--algorithm",
        "lnva",
        "--at",
        "0.2",
        "--duration",
        "0.4",
        "--no-progress",
    ]
    assert main(common + ["--lockable", "none", "--out", str(tmp_path / "a")]) == 0
    assert main(common + ["--lockable", "joint2", "--out", str(tmp_path / "b")]) == 0
    a = json.loads((tmp_path / "a" / "summary.json").read_text())
    b = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert a["meta"]["lockable"] == [["joint2"]]
    assert a["summary"]["jump_at_lock"] == pytest.approx(b["summary"]["jump_at_lock"], rel=1e-12)
    assert a["summary"]["jump_at_lock"] > 0


def test_bench_tables_prints_the_saved_run(tmp_path):
    """scripts/bench_tables.py: one table of medians / p99, one of targets with their verdicts."""
    bench = {
        "schema": "fault_tolerance.bench/1",
        "created": "2026-01-01T00:00:00+00:00",
        "command": "/x/bin/fault-tolerance bench --json b.json",
        "machine": {"cpu": "CPU", "cores": 2, "loadavg": [0.5, 0.4, 0.3]},
        "results": {"arm": {"ops": {"jvja": {"median_us": 1.234, "p99_us": 2.5}}}},
        "targets": [
            {
                "arm": "arm",
                "label": "JVJA / floor",
                "value": 1.31,
                "limit": 1.3,
                "relation": "<=",
                "pass": False,
            },
            {
                "arm": "arm",
                "label": "info row",
                "value": 2.0,
                "limit": 1.5,
                "relation": "<=",
                "pass": None,
            },
        ],
    }
    f = tmp_path / "b.json"
    f.write_text(json.dumps(bench))
    p = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_tables.py"), str(f)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "`fault-tolerance bench --json b.json`" in p.stdout
    assert "| jvja | 1.23 / 2.50 |" in p.stdout
    assert "| arm | JVJA / floor | 1.31 | <= 1.3 | FAIL |" in p.stdout
    assert "info (target not applied here)" in p.stdout
    bad = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_tables.py"), str(ROOT / "README.md")],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "bench_tables: error" in bad.stderr


def test_bench_tables_ratios_are_the_scaling_table(tmp_path):
    """--ratios: one row per arm, medians and the ratios computed from them."""
    ops = {"jacobian": 1.0, "floor": 2.0, "lnva": 2.2, "jvja": 2.4, "sim_jvja": 19.2,
           "sim_jvja_lim": 24.0, "jvja_bounded_free": 3.0}  # fmt: skip
    bench = {
        "schema": "fault_tolerance.bench/1", "created": "2026-01-01T00:00:00+00:00",
        "command": "/x/bin/fault-tolerance bench --json c.json", "machine": {},
        "results": {"chain_7": {"ops": {k: {"median_us": v, "p99_us": v} for k, v in ops.items()}}},
    }  # fmt: skip
    f = tmp_path / "c.json"
    f.write_text(json.dumps(bench))
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "bench_tables.py"), str(f),
                        "--ratios"], capture_output=True, text=True, check=True)  # fmt: skip
    row = next(line for line in p.stdout.splitlines() if line.startswith("| chain_7 "))
    assert row == ("| chain_7 | 1.00 | 2.00 | 2.20 | 2.40 | 1.09 | 1.20 | (none) "
                   "| 19.20 (8.00×) | 24.00 (8.00×) |")  # fmt: skip


def test_inspect_takes_robot_like_the_other_commands(capsys):
    """`inspect --robot NAME` prints what `inspect NAME` prints; none or two robots are refused."""
    assert main(["inspect", "planar_3r"]) == 0
    positional = capsys.readouterr().out
    assert main(["inspect", "--robot", "planar_3r"]) == 0
    assert capsys.readouterr().out == positional
    assert main(["inspect"]) == 2
    assert "name one robot" in capsys.readouterr().err
    assert main(["inspect", "planar_3r", "--robot", "panda"]) == 2


def test_a_reader_that_leaves_ends_the_command_quietly(capsys):
    """`fault-tolerance ... | head`: a BrokenPipeError while printing is exit 0, nothing on stderr
    (it used to be "unexpected error", exit 1)."""
    import argparse

    from fault_tolerance.cli.runner import run_command

    def prints_into_a_closed_pipe(args):
        raise BrokenPipeError(32, "Broken pipe")

    args = argparse.Namespace(debug=False, command="robots")
    assert run_command(prints_into_a_closed_pipe, args) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_lockable_none_on_a_real_arm_from_its_default_start(tmp_path):
    """The UR5e xacro package of tests/data (not ours), default start: `--lockable none` with
    LNVA gives the run `--lockable elbow_joint` gives, and `workspace --lockable none` refuses."""
    import warnings

    from real_arms import cli_args

    base = cli_args("ur5e") + [
        "--joint",
        "elbow_joint",
        "--algorithm",
        "lnva",
        "--at",
        "0.5",
        "--duration",
        "1",
        "--no-progress",
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the description's meshes are not kept in tests/data
        assert main(["lock", *base, "--lockable", "none", "--out", str(tmp_path / "a")]) == 0
        assert main(["lock", *base, "--lockable", "elbow_joint", "--out", str(tmp_path / "b")]) == 0
        a = json.loads((tmp_path / "a" / "summary.json").read_text())
        b = json.loads((tmp_path / "b" / "summary.json").read_text())
        assert a["meta"]["lockable"] == [["elbow_joint"]]
        assert a["summary"] == b["summary"]
        assert (
            main(
                ["workspace", *cli_args("ur5e"), "--lockable", "none", "--out", str(tmp_path / "w")]
            )
            == 2
        )
