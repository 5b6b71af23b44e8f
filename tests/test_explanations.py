"""When no start passes: the refusal names the failed check by category and the joints concerned,
and proposes only fixes whose own start search passed; the servo's lag is no algorithm's error.

The refusals are constructed on the shipped arms and the real descriptions of tests/data (no
Schunk LWA4P or Hello Robot Stretch description is kept there): a lockable joint that is
structurally intolerable, task rows the arm cannot move, a path too fast for the velocity limits
(also the real SO-100 hobby arm with the default circle), locks intolerable under the limits.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from real_arms import ARMS, cli_args, load

import fault_tolerance as ft
from fault_tolerance.cli import main
from fault_tolerance.planning import start_checks as sc
from fault_tolerance.planning.default_start import CHECK_HORIZON, fixes_line, try_fixes
from fault_tolerance.simulation.paths import CirclePath


def test_a_failure_names_a_known_category():
    """A failure category outside CATEGORIES is refused, naming the allowed ones."""
    with pytest.raises(ValueError, match="choose among"):
        sc.Failure("tired", (), "")


def test_the_tally_counts_by_category_and_names_the_dominant_joints():
    """Three too-fast candidates (joint2 each, joint3 once) and one singular: too fast dominates."""
    tally = sc.FailureTally()
    for joints in (("joint2",), ("joint2", "joint3"), ("joint2",)):
        tally.add(sc.Failure(sc.TOO_FAST, joints, "scaled"))
    tally.add(sc.Failure(sc.SINGULAR, (), "near-singular"))
    assert tally.total == 4
    assert tally.dominant() == [(sc.TOO_FAST, 3, ("joint2", "joint3"))]
    text = tally.summary()
    assert text.startswith("4 candidate starts refused: 3 too fast for the velocity limits")
    assert "(joint2, joint3); 1 singular; e.g. scaled" in text
    assert _applied(["--radius", "1", "--omega", "2"], "--radius 0.5") == [
        "--radius", "0.5", "--omega", "2"
    ]  # fmt: skip


def test_the_tally_falls_back_on_the_seeds_when_no_candidate_was_checked():
    """No regular seed: the configurations drawn are counted, by category."""
    tally = sc.FailureTally()
    tally.drawn = 5
    for _ in range(5):
        tally.add_seed(sc.Failure(sc.SINGULAR, (), "near-singular (σ_min(J) = 0 < 0.01)"))
    assert tally.dominant() == [(sc.SINGULAR, 5, ())]
    assert tally.summary().startswith("no regular seed among the 5 configurations drawn")


def test_fix_trials_stop_after_two_that_work_and_report_only_those():
    """A failing fix is tried and not proposed; the trials stop once two fixes work."""
    calls = []

    def attempt(name, works):
        def run():
            calls.append(name)
            if not works:
                raise ft.InvalidInput("no start (still too fast)")

        return run

    fixes = [(f"--opt {k}", attempt(k, k != 1)) for k in range(5)]
    trials = try_fixes(fixes)
    assert calls == [0, 1, 2]
    assert [(t.option, t.works) for t in trials] == [("--opt 0", True), ("--opt 1", False),
                                                     ("--opt 2", True)]  # fmt: skip
    line = fixes_line(trials)
    assert line.startswith("a start passes with --opt 0 or with --opt 2 (that option set so")
    assert "3 fixes tried in" in line
    assert "--opt 1" not in line
    assert try_fixes(fixes, max_trials=1)[0].option == "--opt 0"
    assert "none of the 1 fix tried" in fixes_line(try_fixes(fixes[1:2]))


def test_default_start_refuses_a_path_too_fast_naming_the_joints():
    """A 5 cm circle at 60 rad/s (3 m/s) is beyond the planar 3R's 3 rad/s: too fast, by name."""
    arm = ft.load_arm("planar_3r")
    fast = lambda x0: CirclePath(np.asarray(x0), 0.05, 60.0, 1.0)  # noqa: E731
    with pytest.raises(ft.NoStartFound, match="too fast for the velocity limits") as err:
        ft.default_start(arm, x0=[0.35, 0.0], path=fast, algorithms=("lnva",))
    (category, count, joints), *_ = err.value.reasons
    assert category == sc.TOO_FAST and count >= 1 and set(joints) <= set(arm.joint_names)
    assert joints, "the joints at their velocity limit are named"


def _refusal(argv, capsys) -> str:
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines, "a refusal on stderr"
    return lines[-1]


def _proposed(line: str) -> list[str]:
    """The option texts of "a start passes with A or with B (...)"."""
    m = re.search(r"a start passes with (.*?) \(that option set so", line)
    assert m, f"no working fix proposed: {line}"
    return m.group(1).split(" or with ")


def _applied(argv: list[str], fix: str) -> list[str]:
    """``argv`` with the option of ``fix`` ("--radius 0.5") set to its value (replaced or added)."""
    option, value = fix.split()
    if option not in argv:
        return [*argv, option, value]
    k = argv.index(option)
    return [*argv[: k + 1], value, *argv[k + 2 :]]


def _so100() -> list[str]:
    return cli_args("so100")


#: (argv after `simulate`, category the refusal names, a fix expected among those proposed).
CASES = {
    "structural joint": (
        ["--robot", "spatial_4r", "--lockable", "all"], "structurally", "--lockable joint1,joint2,joint3"
    ),
    "rows the arm cannot move": (
        ["--robot", "panda", "--joints", "panda_joint2,panda_joint4,panda_joint6,panda_joint7",
         "--task", "position"], "singular at every configuration", "--task x,z",
    ),
    "tip on the wrist axis": (
        ["--robot", "ur5", "--tip", "wrist_3_link", "--task", "position"], "structurally",
        "--tip tool0",
    ),
    "too fast": (["--robot", "planar_3r", "--radius", "1", "--omega", "2.5"], sc.TOO_FAST, None),
    "real arm too fast": (None, sc.TOO_FAST, None),
    "locks under limits": (
        ["--robot", "planar_3r", "--radius", "0.8", "--omega", "2"], sc.UNDER_LIMITS, None
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", CASES)
def test_the_refusal_names_the_cause_and_every_proposed_fix_passes(case, capsys):
    """The refusal names the category; each fix it proposes, pasted into the command, runs (0)."""
    argv, category, expected = CASES[case]
    argv = _so100() if argv is None else argv
    base = ["simulate", *argv, "--algorithms", "jvja", "--no-progress"]
    line = _refusal(base, capsys)
    assert category in line, line
    fixes = _proposed(line)
    assert 1 <= len(fixes) <= 2
    if expected:
        assert expected in fixes, line
    for fix in fixes:
        assert main(_applied(base, fix)) == 0, fix
        capsys.readouterr()


def _counts(line: str) -> str:
    """The counts by category of a refusal: "3 path out of reach (joint2); 1 singular"."""
    m = re.search(r"(?:refused|near mid-range): (.*?); e\.g\. ", line)
    assert m, f"no counts in: {line}"
    return m.group(1)


def _reach(arm: ft.Arm) -> float:
    """An upper bound of the distance [m] from the first joint to the tip, from the model alone:
    the distances between successive joint origins and from the last one to the tip frame."""
    model = arm.model
    links = [np.linalg.norm(model.jointPlacements[i].translation) for i in range(2, model.njoints)]
    return float(sum(links) + np.linalg.norm(model.frames[arm.frame_id].placement.translation))


def _assert_every_fix_passes(base: list[str], line: str, capsys) -> list[str]:
    fixes = _proposed(line)
    assert 1 <= len(fixes) <= 2, line
    for fix in fixes:
        assert main(_applied(base, fix)) == 0, fix
        capsys.readouterr()
    return fixes


@pytest.mark.parametrize(
    "duration", [CHECK_HORIZON, pytest.param(2.5 * CHECK_HORIZON, marks=pytest.mark.slow)]
)
def test_a_path_out_of_reach_is_named_so_and_the_fixes_it_proposes_pass(duration, capsys):
    """A 1 m circle from the planar 3R's catalog start (0.35, 0) leaves the arm's 1.5 m reach
    within 2 s. The runs stretch the arm to a singularity on the way, yet the refusal names the
    path out of reach (not a singular arm) and the point asked for, which is farther from the
    base than the links reach (from the model); each fix it proposes, pasted in, runs (exit 0).
    For a task longer than the start's check, the fixes say they were checked over its first
    seconds only."""
    base = ["simulate", "--robot", "planar_3r", "--radius", "1", "--omega", "0.8",
            "--duration", f"{duration:g}", "--algorithms", "jvja", "--no-progress"]  # fmt: skip
    line = _refusal(base, capsys)
    counts = _counts(line)
    assert re.match(rf"\d+ {sc.OUT_OF_REACH}", counts) and sc.SINGULAR not in counts, line
    assert "the path leaves the workspace" in line
    m = re.search(
        r"it asks for x = \[(.*?)\], which no configuration inside the limits reach", line
    )
    assert m, line
    arm = ft.load_arm("planar_3r")
    x = np.array([float(v) for v in m.group(1).split(",")])
    assert np.linalg.norm(x - arm.model.jointPlacements[1].translation[:2]) > _reach(arm)
    capped = f"each a start search over the task's first {CHECK_HORIZON:g} s only"
    assert (capped in line) == (duration > CHECK_HORIZON), line
    fixes = _assert_every_fix_passes(base, line, capsys)
    assert all(f.split()[0] in ("--radius", "--rows") for f in fixes), fixes


def test_a_task_no_joint_moves_is_named_singular_and_the_fixes_it_proposes_pass(capsys):
    """The Panda with only its joints 2, 4, 6, 7 and a position task: they all turn the tool in
    one vertical plane, so J has no y motion anywhere (checked with Pinocchio). The refusal
    names a singular task and the row no joint moves, not a structurally intolerable lock (nor
    its removal as a fix); the fix it proposes, --task x,z, runs (exit 0)."""
    import pinocchio as pin

    joints = "panda_joint2,panda_joint4,panda_joint6,panda_joint7"
    base = ["simulate", "--robot", "panda", "--joints", joints, "--task", "position",
            "--algorithms", "jvja", "--no-progress"]  # fmt: skip
    arm = ft.load_arm("panda", joints=joints.split(","), task="position")
    model, rng = arm.model, np.random.default_rng(3)
    data = model.createData()
    for _ in range(10):
        q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit)
        jac = pin.computeFrameJacobian(model, data, q, arm.frame_id, pin.LOCAL_WORLD_ALIGNED)
        assert np.abs(jac[1]).max() < 1e-12 and np.abs(jac[[0, 2]]).max() > 0.1
    assert sc.still_rows(arm) == ("y",)
    assert sc.intolerable_everywhere(arm, joints.split(",")) == []  # no regular configuration
    line = _refusal(base, capsys)
    counts = _counts(line)
    assert re.fullmatch(rf"\d+ {sc.SINGULAR}", counts), line
    assert "no regular seed among" in line
    assert "the task x/y/z is singular at every configuration" in line
    assert "no joint moves the tool along y;" in line
    assert "structurally" not in line and "remove panda_joint" not in line, line
    assert "--task x,z" in _assert_every_fix_passes(base, line, capsys)


def _lock_argv(name: str) -> tuple[list[str], str]:
    if name in ARMS:
        arm, argv = load(name), cli_args(name) + list(ARMS[name].get("path_args", []))
    else:
        arm, argv = ft.load_arm(name), ["--robot", name]
    lockable = ARMS[name]["lockable"] if name in ARMS and ARMS[name]["lockable"] else None
    joint = (lockable or list(arm.default_lockable))[0]
    return argv, joint if isinstance(joint, str) else joint[0]


def _lock_warnings(name, tmp_path, capsys):
    argv, joint = _lock_argv(name)
    out = tmp_path / "lock"
    assert main(["lock", *argv, "--joint", joint, "--out", str(out), "--no-progress"]) == 0
    cap = capsys.readouterr()
    return cap, json.loads((out / "summary.json").read_text())["warnings"]


@pytest.mark.parametrize("name", ["planar_3r", "spatial_4r", "panda"])
def test_default_lock_does_not_warn_the_servo_lag(name, tmp_path, capsys):
    """`lock` with its default servo and path: no tracking warning before the lock, no lost path
    from the lag (the lag, when above 1 mm, is a note on stdout)."""
    cap, warnings = _lock_warnings(name, tmp_path, capsys)
    kinds = [w["kind"] for w in warnings]
    assert "tracking" not in kinds, cap.err
    assert "lost_path" not in kinds, cap.err


@pytest.mark.slow
@pytest.mark.parametrize("name", list(ARMS))
def test_default_lock_on_real_arms_does_not_warn_the_servo_lag(name, tmp_path, capsys):
    """The same on every real description of tests/data: no tracking warning before the lock."""
    cap, warnings = _lock_warnings(name, tmp_path, capsys)
    assert "tracking" not in [w["kind"] for w in warnings], cap.err
