"""Every option of every command has help text that states its default."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

import numpy as np
import pytest

from fault_tolerance.cli import EXAMPLES, build_parser, main
from fault_tolerance.resolution.mda import MDA_GAIN


def options(parser, path=()):
    """(command path, action) of every option, sub-commands included."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from options(sub, (*path, name))
        elif action.option_strings and not isinstance(
            action, (argparse._HelpAction, argparse._VersionAction)
        ):
            yield " ".join(path), action


def test_every_option_has_help_stating_its_default():
    """Walking the parser tree: no option without help, none whose help omits its default (a
    required option says it is required instead)."""
    found = list(options(build_parser()))
    assert len(found) > 50
    missing = [(cmd, a.option_strings[-1]) for cmd, a in found if not a.help]
    silent = [
        (cmd, a.option_strings[-1])
        for cmd, a in found
        if "default" not in a.help.lower() and not (a.required and "(required)" in a.help)
    ]
    assert missing == [] and silent == [], (missing, silent)


@pytest.mark.parametrize(
    ("command", "option", "number"),
    [
        ("simulate", "--gain", f"{MDA_GAIN:g}"),
        ("lock", "--gain", f"{MDA_GAIN:g}"),
        ("simulate", "--feedback", "0 for simulate"),
        ("lock", "--feedback", "10 for lock"),
        ("simulate", "--dt", "0.001"),
        ("lock", "--tau", "0.05"),
        ("lock", "--at", "default: max"),
        ("lock", "--algorithm", "default: lnva"),
    ],
)
def test_the_issue_options_state_their_default_value(command, option, number):
    """--gain, --feedback, --dt, --tau, --at and --algorithm give the default's value."""
    helps = {(c, a.option_strings[-1]): a.help for c, a in options(build_parser())}
    assert number in helps[(command, option)], helps[(command, option)]


# -- the examples of every --help run ------------------------------------------------------

ROOT = Path(__file__).resolve().parents[1]
#: Options that shorten an example (replacing its own value, or added): the command it runs is the
#: example's, on a shorter path, a coarser grid or fewer timed calls.
SHORTER = {
    "simulate": {"--duration": "0.05", "--no-progress": None},
    "lock": {"--duration": "0.5", "--no-progress": None},
    "reproduce": {"--quick": None, "--cases": "fig2", "--no-progress": None},
    "workspace": {"--grid": "21", "--workers": "0", "--no-progress": None},
    "design": {"--candidates": "4", "--rounds": "1", "--grid": "21", "--workers": "0",
               "--no-progress": None},
    "bench": {"--robots": "planar_3r", "--steps": "3", "--warmup": "1",
              "--batch-configurations": "0"},
}  # fmt: skip
#: The same for a DH design (``design --vary dh``): one population, no pattern search.
SHORTER_DH = {"--popsize": "4", "--generations": "0", "--rounds": "0", "--workers": "0",
              "--no-progress": None}  # fmt: skip
#: Examples that need what a test cannot give (a live viewer, a Dask cluster): parsed, not run.
PARSED_ONLY = ("--open", "--scheduler")


def shorten(argv: list[str], extra: dict) -> list[str]:
    """``argv`` with each option of ``extra`` given its value (replaced if present, else added)."""
    out = list(argv)
    for opt, value in extra.items():
        if opt in out:
            i = out.index(opt)
            if value is not None:
                out[i + 1] = value
        else:
            out += [opt] if value is None else [opt, value]
    return out


def example_lines() -> list[tuple[str, list[str]]]:
    """(command, argv) of every line of every command's ``example:`` block."""
    found = []
    for cmd, text in EXAMPLES.items():
        for line in text.splitlines():
            words = shlex.split(line)
            assert words[:2] == ["fault-tolerance", cmd], line
            found.append((cmd, words[1:]))
    return found


def _example_files(folder: Path) -> None:
    """The files the examples name: my_arm.urdf (a copy of the shipped 4R), its path.csv, and the
    UR5e xacro package of the test data (``ur_description/``)."""
    import shutil

    shutil.copy(ROOT / "robots" / "spatial_4r.urdf", folder / "my_arm.urdf")
    shutil.copytree(ROOT / "tests" / "data" / "robots" / "ur5e" / "ur_description",
                    folder / "ur_description")  # fmt: skip
    t = np.linspace(0.0, 0.2, 21)
    x0 = np.array([-0.21, 0.20, 0.35])
    rows = [(ti, *(x0 + 0.02 * np.array([np.cos(2 * np.pi * ti) - 1, np.sin(2 * np.pi * ti), 0])))
            for ti in t]  # fmt: skip
    (folder / "path.csv").write_text(
        "t,x,y,z\n" + "".join(",".join(f"{v:.9g}" for v in r) + "\n" for r in rows)
    )


@pytest.mark.slow
def test_every_help_example_runs(tmp_path, monkeypatch, capsys):
    """Every line of every command's ``example:`` runs, shortened, and exits 0 (in --help's order,
    in one folder: replay plays what simulate wrote, compare reads what bench wrote)."""
    monkeypatch.chdir(tmp_path)
    _example_files(tmp_path)
    lines = example_lines()
    assert {cmd for cmd, _ in lines} == set(EXAMPLES) and len(lines) >= 20
    for cmd, argv in lines:
        if any(opt in argv for opt in PARSED_ONLY):
            build_parser().parse_args(argv)
            continue
        dh = (
            cmd == "design" and "--vary" in argv and argv[argv.index("--vary") + 1].startswith("dh")
        )
        code = main(shorten(argv, SHORTER_DH if dh else SHORTER.get(cmd, {})))
        err = capsys.readouterr().err
        assert code == 0, (argv, err)
    assert (tmp_path / "replay.html").stat().st_size > 100_000
    assert (tmp_path / "out" / "mine").is_dir() and (
        tmp_path / "out" / "d" / "design.json"
    ).exists()


def test_every_help_shows_its_example(capsys):
    """`COMMAND --help` ends with an example: block holding every line of that command's example."""
    for cmd, text in EXAMPLES.items():
        with pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0
        out = capsys.readouterr().out
        assert "example:" in out
        for line in text.splitlines():
            assert line.strip() in out, (cmd, line)


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--robot", "planar_3r", "--lockable", "joint1", "--lockable", "joint2"],
        ["simulate", "--robot", "planar_3r", "--html", "--html"],
        ["lock", "--robot", "planar_3r", "--joint", "joint2", "--at=0.1", "--at", "0.2"],
        ["simulate", "--robot", "planar_3r", "--robot", "spatial_4r"],
        ["bench", "--steps", "3", "--steps", "4"],
    ],
)
def test_an_option_given_twice_is_refused(argv, capsys):
    """A value option or a flag given twice exits 2 with one line "given twice"."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "given twice" in err and err.count("\n") == 1, err


def test_repeatable_options_merge():
    """--package-dir and --xacro-arg may repeat: their values are merged in order."""
    args = build_parser().parse_args(
        ["inspect", "x.urdf", "--package-dir", "a", "--package-dir", "b",
         "--xacro-arg", "hand:=true", "--xacro-arg", "arm_id:=fr3"]
    )  # fmt: skip
    assert args.package_dir == ["a", "b"] and args.xacro_arg == ["hand:=true", "arm_id:=fr3"]
    assert not hasattr(args, "_options_given")


def test_design_help_names_only_the_task_it_accepts(tmp_path, capsys):
    """design --help offers --task circle only (no planar | position | pose | rows), and that is
    what it accepts."""
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    out = capsys.readouterr().out
    task = out[out.index("  --task") :].split("\n  --")[0]
    assert "circle" in task and "pose" not in task and "rows" not in task
    assert (
        main(["design", "--robot", "planar_3r", "--task", "pose", "--out", str(tmp_path / "d")])
        == 2
    )
    assert "is not one of ['circle']" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, allowed",
    [
        (["simulate", "--robot", "planar_3r", "--dt", "0.01", "--dt", "0.02"],
         "only --package-dir, --xacro-arg and --option may repeat"),
        (["replay", "run", "--speed", "1", "--speed", "2"], "only --package-dir may repeat"),
        (["bench", "--steps", "3", "--steps", "4"], "no option of this command may repeat"),
    ],
)  # fmt: skip
def test_given_twice_names_every_option_that_may_repeat(argv, allowed, capsys):
    """The "given twice" line lists the command's repeatable options, --option among them."""
    from fault_tolerance.cli.runner import repeatable

    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert allowed in capsys.readouterr().err
    sub = build_parser()._subparsers._group_actions[0].choices[argv[0]]
    assert all(opt in allowed for opt in repeatable(sub))


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--option", "gain=0.02", "--option", "gain=0.5"],
         "--option gain given twice (gain=0.02 and 'gain=0.5'); give it once"),
        (["--gain", "0.02", "--option", "gain=0.5"],
         "--gain and --option 'gain=0.5' set the same option; give one of them"),
        (["--response", "continuation", "--option", "response=least_norm"],
         "--response and --option 'response=least_norm' set the same option"),
    ],
)  # fmt: skip
def test_an_option_set_twice_through_option_is_refused(extra, message, tmp_path, capsys):
    """The same resolver option twice (by --option, or by its flag and --option): exit 2."""
    argv = ["simulate", "--robot", "planar_3r", "--algorithms", "mda,jvja", "--duration", "0.05",
            "--no-progress", "--out", str(tmp_path / "s"), *extra]  # fmt: skip
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "s").exists()


def test_given_options_records_the_flags_given_not_the_defaults():
    """given_options holds the destinations of the options on the command line only."""
    args = build_parser().parse_args(["simulate", "--robot", "planar_3r", "--gain", "0.1"])
    assert {"robot", "gain"} <= args.given_options
    assert "response" not in args.given_options and args.response == "least_norm"


def test_design_candidates_help_states_the_rounding(tmp_path, capsys):
    """--candidates C with d varied parameters evaluates max(4, ceil(C/d))·d first designs."""
    import json
    import math

    with pytest.raises(SystemExit):
        main(["design", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "max(4, ceil(C/d))·d designs" in out
    argv = ["design", "--robot", "planar_3r", "--candidates", "33", "--rounds", "0", "--grid",
            "21", "--workers", "0", "--no-progress", "--out", str(tmp_path / "d")]  # fmt: skip
    assert main(argv) == 0
    d = 5  # the planar 3R's --vary limits: five free limits
    evaluations = json.loads((tmp_path / "d" / "design.json").read_text())["evaluations"]
    assert evaluations == max(4, math.ceil(33 / d)) * d == 35
