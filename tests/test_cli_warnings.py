"""A bad run cannot end silently: simulate and lock print one warning line per problem and
record them in summary.json; an error raised under a progress bar gets a line of its own, once."""

from __future__ import annotations

import json

import pytest

from fault_tolerance.cli import main
from fault_tolerance.errors import InvalidInput

PREFIX = "fault-tolerance simulate: warning: "


def test_bad_simulate_warns_once_per_problem(tmp_path, capsys):
    """A circle out of reach: one stderr line per problem, the same ones in summary.json. The
    paper's formulation (--no-limits): under the joint limits no rate is over the speed limit."""
    out = tmp_path / "bad"
    argv = ["simulate", "--robot", "planar_3r", "--x0", "1.3,0", "--radius", "0.3", "--no-limits"]
    argv += ["--algorithms", "jvja", "--duration", "0.5", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    lines = [line for line in err if line.startswith(PREFIX + "jvja: ")]
    assert len(lines) == len(err), err  # nothing else on stderr
    record = json.loads((out / "jvja" / "summary.json").read_text())
    assert {"meta", "summary", "warnings"} <= set(record)
    kinds = [w["kind"] for w in record["warnings"]]
    assert {"over_speed", "rcn", "tracking"} <= set(kinds)
    assert [PREFIX + "jvja: " + w["message"] for w in record["warnings"]] == lines


def test_good_simulate_is_quiet(tmp_path, capsys):
    """The paper's Fig. 2 case prints no warning and records an empty list."""
    out = tmp_path / "good"
    argv = ["simulate", "--robot", "planar_3r", "--algorithms", "lnva,jvja"]
    argv += ["--out", str(out), "--no-progress"]
    assert main(argv) == 0
    assert "warning" not in capsys.readouterr().err
    for alg in ("lnva", "jvja"):
        assert json.loads((out / alg / "summary.json").read_text())["warnings"] == []


def test_lock_notes_the_servo_lag_apart_from_the_warnings(tmp_path, capsys):
    """A 50 ms servo lag puts the tool millimetres off the planar circle before the lock: a note
    on stdout with the lag-free error beside it, not a tracking warning (the algorithm tracks)."""
    import re

    out = tmp_path / "lock"
    argv = ["lock", "--robot", "planar_3r", "--joint", "joint2", "--at", "0.5"]
    argv += ["--out", str(out), "--no-progress"]
    assert main(argv) == 0
    cap = capsys.readouterr()
    notes = [line for line in cap.out.splitlines() if line.startswith("note: servo lag: ")]
    assert len(notes) == 1, cap.out
    m = re.search(r"servo model ([\d.]+) mm before the lock \(([\d.]+) mm with perfect", notes[0])
    assert m, notes[0]
    with_servo, lag_free = map(float, m.groups())
    assert with_servo > 1.0 > lag_free
    err = cap.err.splitlines()
    assert all(line.startswith("fault-tolerance lock: warning: lnva: ") for line in err)
    kinds = [w["kind"] for w in json.loads((out / "summary.json").read_text())["warnings"]]
    assert "tracking" not in kinds and "lost_path" not in kinds and len(kinds) == len(err)


def test_error_under_a_progress_bar_has_its_own_line(monkeypatch, capsys):
    """An error raised while the bar is drawn starts a new line and is printed once."""
    import fault_tolerance.simulation.simulate as simulation

    def failing(*args, progress=None, **kwargs):
        for _ in range(5):
            progress.update(1)
        raise InvalidInput("the path left the workspace")

    monkeypatch.setattr(simulation, "simulate", failing)
    # an explicit start: the default-start search would call the fake simulate without a bar
    argv = ["simulate", "--robot", "planar_3r", "--algorithms", "jvja", "--q0", "0.3,1.2,1.0"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    message = "fault-tolerance simulate: error: the path left the workspace"
    assert err.count(message) == 1
    assert err.startswith(message) or f"\n{message}" in err, repr(err)
    assert err.rstrip("\n").endswith(message), repr(err)  # the bar is not drawn again after it


@pytest.mark.parametrize("quick_case", ["fig4"])
def test_reproduce_lists_warnings(tmp_path, capsys, quick_case):
    """reproduce records a (here empty) warnings list in summary.json and in each run's."""
    assert main(["reproduce", "--quick", "--cases", quick_case, "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["warnings"] == [] and "warning" not in capsys.readouterr().err
    run = json.loads((tmp_path / "runs" / quick_case / "jvja" / "summary.json").read_text())
    assert run["warnings"] == []


def test_report_names_degenerate_starts(tmp_path):
    """REPORT.md's start-sensitivity section names each degenerate start with its warnings."""
    from fault_tolerance.paper.reproduce import reproduce

    summary = reproduce(tmp_path, cases=["fig3"], quick=True, progress=False)
    sens = summary["details"]["fig3"]["start_sensitivity"]
    report = (tmp_path / "REPORT.md").read_text()
    for i in sens["degenerate_starts"]:
        assert f"fig3, start {i + 1} (q0 = [" in report
    kept = [s for s in sens["starts"] if not s["degenerate"]]
    assert f"% of {len(kept)} |" in report
    assert sens["jvja_smaller_fraction"] == pytest.approx(
        sum(s["jvj_mean_jvja"] <= s["jvj_mean_lnva"] for s in kept) / len(kept)
    )
