"""The opt-in workspace rows of the benchmark: runs the command on one and two workers.

No timing is asserted here: the 1.7x and 30 s targets are the benchmark's PASS/FAIL lines.
"""

from __future__ import annotations

import pytest

from fault_tolerance.bench import command as bench_command
from fault_tolerance.bench import workspace as workspace_bench


def test_bad_grid_exits_2(capsys):
    """``--workspace 1`` is refused with a one-line message."""
    assert bench_command.main(["--robots", "planar_3r", "--workspace", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--workspace GRID must be >= 2" in err


@pytest.mark.slow
def test_rows_time_one_and_two_workers_on_identical_maps(monkeypatch):
    """Three runs of the command (small map, one worker, two workers); identical maps; two
    target rows; CPU totals that count the worker processes too."""
    monkeypatch.setattr(workspace_bench, "SMALL_GRID", 21)
    r = workspace_bench.bench_workspace(31)
    assert r["identical"] is True and r["grid"] == 31
    assert "--grid 31 --chunks 32 --workers 2" in r["command"]
    for run in ("small", "one", "two"):
        assert r[run]["wall_s"] > 0 and r[run]["user_s"] > 0
    assert r["speedup"] == r["one"]["wall_s"] / r["two"]["wall_s"]
    items = workspace_bench.target_items(r)
    assert [t["name"] for t in items] == ["workspace_201_one_worker_s", "workspace_two_over_one"]
    assert items[1]["pass"] == (r["speedup"] >= 1.7)
    text = workspace_bench.format_workspace(r)
    assert "2 workers" in text and "s CPU" in text and "identical" in text


def test_a_failing_run_raises_with_its_last_line(tmp_path):
    """A command that fails is reported with the last line of its stderr."""
    cmd = workspace_bench.command(21, 1, tmp_path / "x")
    cmd[cmd.index("--grid") + 1] = "1"
    with pytest.raises(workspace_bench.FaultToleranceError, match="grid"):
        workspace_bench._timed(cmd)
